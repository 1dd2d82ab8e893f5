"""The names and defaults of the training commands' options, without PyTorch: ``wise train`` and
``wise data`` check their arguments against these before the training code loads."""

SAMPLINGS = ("uniform", "presets", "mixture")
"""How a global training example's parameters are drawn (:mod:`wise.train.data`)."""
MIXTURE_PRESET_SHARE = 0.3
"""Share of the examples drawn around a preset by the ``mixture`` sampling."""
PROCEDURAL_SHARE = 0.25
"""Default share of the training examples on dead-leaves pictures instead of photos."""
LOSSES = ("image-l1", "image-l2", "param-l1", "param-l2")
"""The losses of global training (:mod:`wise.train.losses`)."""
GAN_LOSSES = ("lsgan", "vanilla")
"""The adversarial losses of local training (:mod:`wise.train.discriminator`)."""
LR_SCHEDULES = ("constant", "cosine", "linear")
DIRECTIONS = ("AtoB", "BtoA")
"""pix2pix's ``--direction``: which side of a pair is the input (``photo``)."""
TASK_FILE = "task.json"
"""Written by ``wise data adaptive`` into a pairs folder: the task, its effect and preset."""
ADAPTIVE_SPLITS = ("train", "test")
"""The split folders ``wise data adaptive`` writes (pix2pix's names)."""
MIN_CHANGE = 0.005
"""Default least mean absolute difference between a pair's target and the preset's rendering of
its photo: on flat or abstract pictures the change does not show (XDoG draws nothing there),
and such a pair teaches a network nothing."""
DESCRIPTION_FILE = "drawing.json"
"""Written by ``wise data drawing`` into a pairs folder: how its drawings were made."""
