"""Classical (non-deep) methods: NMF solvers for motion clustering (thesis §6.3) and their sample graphs."""
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
    "GNMF",
    "NMC",
    "NMF",
    "OrthogonalNMF",
    "combine_graphs",
    "knn_graph",
    "label_graph",
    "laplacian",
    "sparse_graph",
    "split_laplacian",
]
