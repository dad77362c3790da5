"""Errors that carry a message meant for a user, not a traceback."""


class SimrealError(Exception):
    """Base class: the message says what was wrong and, where possible, what was expected."""


class ImageFormatError(SimrealError):
    """An image message whose encoding, step, size and data length disagree."""


class CameraInfoError(SimrealError):
    """Camera intrinsics that cannot describe a camera (zero focal length, zero size, ...)."""


class SceneError(SimrealError):
    """A scene file that does not validate; the message names the key, expected and found."""


class ModelFileError(SimrealError):
    """A model file that is missing, truncated, corrupt or of the wrong schema."""


class BagError(SimrealError):
    """A bag that cannot be opened or read."""


class FemError(SimrealError):
    """A finite-element problem that is ill-posed (no supports, singular, diverging Newton)."""
