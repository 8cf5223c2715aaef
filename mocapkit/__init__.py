"""mocapkit: a PyTorch + Lightning training suite for human motion data.

Subpackages:
    datasets    file formats, synthetic stand-ins, protocols, Lightning data modules
    models      networks and layers (3D energy image, VGG-style motion CNN)
    train       Lightning modules and the train / eval / export / predict entry points
    evaluation  metrics, tables and plots
"""

__version__ = "0.1.0"
