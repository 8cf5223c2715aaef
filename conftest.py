"""pytest's root conftest: its presence puts the repository root on ``sys.path``, so the tests import
their helpers as ``tests.shared_data`` under plain ``pytest`` as under ``python -m pytest``."""
