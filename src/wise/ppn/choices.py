"""The names of the networks and of their options, without PyTorch: the ``wise`` commands check
their arguments against these before the networks load."""

ARCHITECTURE_NAMES = ("simple", "stats", "tone", "resnet", "multifeature")
"""The global networks (:data:`wise.ppn.ARCHITECTURES`)."""
LOCAL_ARCHITECTURE_NAMES = ("unet",)
"""The local networks (:data:`wise.ppn.LOCAL_ARCHITECTURES`)."""
PPN_KINDS = ("local", "preset")
"""The translator's first stage: ``local``, masks painted by a local PPN; ``preset``, the
effect's fixed preset everywhere (:mod:`wise.ppn.translation`)."""
POST_NETWORK_NAMES = ("resnet", "unet")
"""The translator's CNNs after the effect (:data:`wise.ppn.postprocess.POST_NETWORKS`)."""
NO_POST = "none"
POST_KINDS = (*POST_NETWORK_NAMES, NO_POST)
POST_WIDTH = 64
"""Channels of the first layer of a CNN after the effect (pix2pix's ``ngf``)."""
