"""Moving prepared data to and from other toolkits' formats, without code.

``pyskl``   pyskl / MMAction2 skeleton annotation pickles <-> NTU caches
            (:func:`~mocapkit.datasets.interop.pyskl.export_pyskl`,
            :func:`~mocapkit.datasets.interop.pyskl.import_pyskl`; ``mocapkit pyskl export|import``)
"""

from mocapkit.datasets.interop.pyskl import (
    PysklFormatError,
    PysklImportReport,
    export_pyskl,
    import_pyskl,
)

__all__ = ["PysklFormatError", "PysklImportReport", "export_pyskl", "import_pyskl"]
