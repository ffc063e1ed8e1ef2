"""Remove rolling-shutter skew (horizontal shear) from photos and video frames of people.

The face is the ruler: ``unshear`` finds each face, locates its eyes, nose and mouth with a small
landmark network, reads the shear ``k`` of ``x' = x + k (y - H/2)`` from them, and shifts every
row back. The built-in models are compiled into the package.

    import unshear
    u = unshear.Unshear()                       # built once, reused; thread-safe
    report = u.estimate(image)                  # numpy uint8/uint16: HxW, HxWx3, HxWx4
    fixed = u.correct(image, report=report)     # the input's layout and dtype

Images are RGB by default; pass ``bgr=True`` for OpenCV's BGR arrays. Every call releases the
GIL while it works. See ``docs/python.md`` in the repository.
"""

from ._unshear import (
    DEFAULT_MAX_PIXELS,
    Face,
    Frame,
    NoFaceError,
    Report,
    Unshear,
    VideoCorrector,
    __version__,
    distort,
    options,
    read,
    write,
)

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "Face",
    "Frame",
    "NoFaceError",
    "Report",
    "Unshear",
    "VideoCorrector",
    "__version__",
    "distort",
    "options",
    "read",
    "write",
]
