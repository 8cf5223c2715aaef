"""Networks and layers."""
from mocapkit.models.energy_image import EnergyImage
from mocapkit.models.energy_vgg import EnergyImageClassifier, EnergyVGG, energy_image_vgg, energy_vgg

__all__ = ["EnergyImage", "EnergyImageClassifier", "EnergyVGG", "energy_image_vgg", "energy_vgg"]
