"""Networks and layers."""
from mocapkit.models.clip_bow import ClipNMFBagOfWords, clip_nmf_bow
from mocapkit.models.energy_image import EnergyImage
from mocapkit.models.energy_vgg import EnergyImageClassifier, EnergyVGG, energy_image_vgg, energy_vgg
from mocapkit.models.gait_cnn import MultiTaskGaitCNN, multitask_gait_cnn
from mocapkit.models.nmf_layer import NMFLayer

__all__ = [
    "ClipNMFBagOfWords", "EnergyImage", "EnergyImageClassifier", "EnergyVGG", "MultiTaskGaitCNN", "NMFLayer",
    "clip_nmf_bow", "energy_image_vgg", "energy_vgg", "multitask_gait_cnn",
]
