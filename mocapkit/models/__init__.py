"""Networks and layers."""

from mocapkit.models.clip_bow import ClipNMFBagOfWords, clip_nmf_bow
from mocapkit.models.energy_image import EnergyImage
from mocapkit.models.energy_vgg import EnergyImageClassifier, EnergyVGG, energy_image_vgg, energy_vgg
from mocapkit.models.gait_cnn import MultiTaskGaitCNN, multitask_gait_cnn
from mocapkit.models.nmf_layer import NMFLayer
from mocapkit.models.refiners import BiGRURefiner, MaskedTransformerRefiner, refine_bigru, refine_transformer

__all__ = [
    "BiGRURefiner",
    "ClipNMFBagOfWords",
    "EnergyImage",
    "EnergyImageClassifier",
    "EnergyVGG",
    "MaskedTransformerRefiner",
    "MultiTaskGaitCNN",
    "NMFLayer",
    "clip_nmf_bow",
    "energy_image_vgg",
    "energy_vgg",
    "multitask_gait_cnn",
    "refine_bigru",
    "refine_transformer",
]
