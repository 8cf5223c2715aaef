"""Classical (non-learned) methods, scikit-learn style: NMF solvers for motion clustering (thesis §6.3) and
their sample graphs; the GEI + PCA + LDA gait baseline."""
from mocapkit.classical.gei_pca_lda import GEIPCALDA, run_gei_pca_lda
from mocapkit.classical.graphs import (
    combine_graphs,
    knn_graph,
    label_graph,
    laplacian,
    sparse_graph,
    split_laplacian,
)
from mocapkit.classical.nmf import GNMF, NMC, NMF, OrthogonalNMF

__all__ = [
    "GEIPCALDA",
    "GNMF",
    "NMC",
    "NMF",
    "OrthogonalNMF",
    "combine_graphs",
    "knn_graph",
    "label_graph",
    "laplacian",
    "run_gei_pca_lda",
    "sparse_graph",
    "split_laplacian",
]
