"""Classical (non-learned) methods, all scikit-learn estimators (parameters stored untouched in ``__init__``,
input checks in ``fit``, fitted attributes ending in ``_``, ``NotFittedError`` before ``fit``): NMF solvers for
motion clustering (thesis §6.3) and their sample graphs; the bag-of-clip-words classifier; the GEI + PCA + LDA
gait baseline; Kinect posture reconstruction (Zhou 2014 ch. 5), its random-forest baseline and the Kinect SDK's
smoothing filter.
:mod:`mocapkit.evaluation.compare` runs them beside the learned models on the same splits."""
from mocapkit.classical.bag_of_words import (
    BagOfWordsClassifier,
    ClipConditioner,
    SequenceClips,
)
from mocapkit.classical.dynammo import DynaMMo
from mocapkit.classical.feature_selection import AMFS, SPEC, UDFS, LaplacianScore
from mocapkit.classical.filter_bases import FilterBasesRefiner
from mocapkit.classical.gap_filling import (
    HoldLastValue,
    LinearInterpolation,
    PCAGapFilling,
    PchipInterpolation,
    SplineInterpolation,
)
from mocapkit.classical.gei_pca_lda import GEIPCALDA
from mocapkit.classical.graphs import (
    combine_graphs,
    knn_graph,
    label_graph,
    laplacian,
    sparse_graph,
    split_laplacian,
)
from mocapkit.classical.kinect_reconstruction import (
    DoubleExponentialSmoother,
    KinectPostureReconstructor,
    RandomForestPoseCorrector,
)
from mocapkit.classical.ksvd import KSVD
from mocapkit.classical.lrmf import LRMF
from mocapkit.classical.nmf import GNMF, NMC, NMF, OrthogonalNMF
from mocapkit.classical.pose_prior import PosePriorRefiner
from mocapkit.classical.psc import PSCRefiner
from mocapkit.classical.svt import SVTCompletion
from mocapkit.classical.trnn import TrNN

__all__ = [
    "AMFS",
    "GEIPCALDA",
    "GNMF",
    "KSVD",
    "LRMF",
    "NMC",
    "NMF",
    "SPEC",
    "UDFS",
    "BagOfWordsClassifier",
    "ClipConditioner",
    "DoubleExponentialSmoother",
    "DynaMMo",
    "FilterBasesRefiner",
    "HoldLastValue",
    "KinectPostureReconstructor",
    "LaplacianScore",
    "LinearInterpolation",
    "OrthogonalNMF",
    "PCAGapFilling",
    "PSCRefiner",
    "PchipInterpolation",
    "PosePriorRefiner",
    "RandomForestPoseCorrector",
    "SVTCompletion",
    "SequenceClips",
    "SplineInterpolation",
    "TrNN",
    "combine_graphs",
    "knn_graph",
    "label_graph",
    "laplacian",
    "sparse_graph",
    "split_laplacian",
]
