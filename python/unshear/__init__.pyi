"""Type stubs of ``unshear`` (the compiled module ``unshear._unshear``, re-exported)."""

import os
from collections.abc import Iterable
from typing import Any, ClassVar, Literal, final

import numpy as np
import numpy.typing as npt
from typing_extensions import TypeAlias

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

__version__: str
DEFAULT_MAX_PIXELS: int
"""The largest image accepted by default: 250,000,000 pixels (as the CLI's ``--max-pixels``)."""

Image: TypeAlias = npt.NDArray[np.uint8] | npt.NDArray[np.uint16]
"""An image array: H x W (grey), or H x W x C with C = 1 (grey), 2 (grey + alpha), 3 (RGB, or
BGR with ``bgr=True``) or 4 (RGBA / BGRA); ``uint8`` or ``uint16``; any strides."""

ImageLike: TypeAlias = npt.NDArray[Any]
"""What the functions take: any numpy array, so that OpenCV's images (typed ``MatLike``) and
arrays of computed dtype pass a type checker; at run time it must be an :data:`Image`
(``uint8`` or ``uint16``), or ``ValueError`` is raised."""

PathLike: TypeAlias = str | os.PathLike[str]
Point: TypeAlias = tuple[float, float]
Detector: TypeAlias = Literal["network", "viola-jones"]
Locator: TypeAlias = Literal["network", "filters"]
Search: TypeAlias = Literal["thorough", "quick", "single"]
ShearModel: TypeAlias = Literal["equation5", "shear-roll", "shear-roll-yaw"]
FilterType: TypeAlias = Literal["umace", "asef", "mosse"]
Region: TypeAlias = Literal["image", "face"]
Canvas: TypeAlias = Literal["same", "expand", "crop"]
Interp: TypeAlias = Literal["linear", "cubic"]

class NoFaceError(ValueError):
    """No face gave an accepted estimate and no shear was given: nothing to correct by."""

    report: Report | None
    """What was found (the faces, and why each was refused), raised by ``Unshear.correct`` and
    ``Unshear.correct_file``: the record of the image without estimating it again."""

@final
class Face:
    """One face: where it is, its landmarks and its shear.

    Points are ``(x, y)`` in the input's pixels, origin top left; the subject's right eye is on
    the image's left.
    """

    @property
    def box(self) -> tuple[float, float, float, float]:
        """The face box ``(x, y, width, height)``."""
    @property
    def right_eye(self) -> Point:
        """The subject's right eye (on the image's left)."""
    @property
    def left_eye(self) -> Point:
        """The subject's left eye (on the image's right)."""
    @property
    def right_nostril(self) -> Point:
        """The subject's right nostril."""
    @property
    def left_nostril(self) -> Point:
        """The subject's left nostril."""
    @property
    def nose(self) -> Point | None:
        """The nose point (the lower nose), or ``None`` when the locator gives none."""
    @property
    def mouth(self) -> Point | None:
        """The mouth centre, or ``None``."""
    @property
    def k(self) -> float | None:
        """This face's shear, ``None`` when refused (confidence below ``min_confidence``)."""
    @property
    def k_measured(self) -> float:
        """The shear measured, refused or not."""
    @property
    def roll(self) -> float:
        """The head's roll in degrees (positive: the subject's left eye, image right, lower)."""
    @property
    def confidence(self) -> float:
        """The chance (0 to 1) that the estimate is within 0.10 of the true shear."""
    @property
    def face_score(self) -> float | None:
        """The landmark network's face score (0 to 1); ``None`` with ``locator="filters"``."""
    @property
    def refused(self) -> str | None:
        """Why ``k`` is ``None`` (``"low_confidence"``, ``"implausible_shear"``, ...), or ``None``."""
    @property
    def outvoted(self) -> bool:
        """Whether the image's shear came from other faces that disagree with this one's."""
    def to_dict(self) -> dict[str, Any]:
        """The face with the CLI's ``--json`` keys (points as ``[x, y]`` lists, not rounded)."""
    # Compared by value, so unhashable; pickled and copied whole (every property, not only
    # those of to_dict()).
    __hash__: ClassVar[None]  # type: ignore[assignment]
    def __eq__(self, value: object, /) -> bool: ...

@final
class Report:
    """What was found in one image."""

    @property
    def k(self) -> float | None:
        """The image's shear (from the consistent majority of its faces' accepted estimates), or
        ``None`` when no face gave one."""
    @property
    def faces(self) -> list[Face]:
        """Every face found, with its estimate."""
    @property
    def width(self) -> int:
        """The image's width in pixels."""
    @property
    def height(self) -> int:
        """The image's height in pixels."""
    @property
    def faces_disagree(self) -> bool:
        """Whether the faces' estimates disagree with no consistent majority (``k`` is ``None``)."""
    @property
    def readout(self) -> Literal["rows", "columns"]:
        """``"rows"``, or ``"columns"`` for a photo its EXIF orientation turns a quarter (a
        phone held upright; ``estimate_file``), read out column by column: ``k`` is then the
        vertical shear ``y' = y + k x``, and ``correct`` undoes it so."""
    @property
    def k_source(self) -> Literal["faces", "faces+scene", "scene"] | None:
        """Which rulers made ``k``; ``None`` when ``k`` is."""
    @property
    def scene_k(self) -> float | None:
        """The shear the scene's verticals give (see ``ruler``), or ``None``."""
    @property
    def scene_uncertainty(self) -> float | None:
        """One standard deviation of ``scene_k``."""
    @property
    def scene_disagrees(self) -> bool:
        """Whether the faces and the scene disagree beyond their uncertainties (the faces made
        ``k``: the subject moved differently from the camera)."""
    @property
    def k_rows(self) -> list[tuple[float, float]] | None:
        """``[(row, k), (row, k)]``: the shear at the highest and the lowest face's row when
        faces at different heights disagree beyond their uncertainty (linear between, held
        beyond; ``k`` is then its value at the middle row), or ``None``."""
    @property
    def warnings(self) -> list[str]:
        """What the caller should know about this image (views skipped, data missing, ...)."""
    def to_dict(self) -> dict[str, Any]:
        """``{"k": ..., "faces": [...]}`` with the CLI's ``--json`` keys (``k_source``,
        ``scene_k``, ``scene_uncertainty``, ``scene_disagrees``, ``k_rows`` when set), not
        rounded."""
    # Compared by value, so unhashable; pickled and copied whole (every property, not only
    # those of to_dict()).
    __hash__: ClassVar[None]  # type: ignore[assignment]
    def __eq__(self, value: object, /) -> bool: ...

@final
class Unshear:
    """The rolling-shutter corrector: the built-in models with one set of settings.

    Build it once and reuse it: construction loads the models (tens of milliseconds). One
    object may be used from any number of threads at once; every call releases the GIL.

    The settings mirror the CLI's options, with the CLI's defaults:

    * ``detector``: what finds the faces: ``"network"`` (the built-in detector trained on
      sheared and rolled faces: one pass, and a second over the image de-sheared by the shear
      its faces measure) or ``"viola-jones"`` (the paper's cascade)
      (``--detector``; default ``None``: the network, or Viola-Jones when ``search`` or the
      filters ask for it).
    * ``locator``: what locates the eyes, nose and mouth: the landmark ``"network"`` (default)
      or the paper's correlation ``"filters"`` (``--locator``).
    * ``search``: Viola-Jones only: ``"quick"`` (default: the image as it is, other views when
      it shows no trusted face), ``"thorough"`` (``--thorough``: every de-sheared and turned
      view of every image, about 20 times slower than the network detector) or ``"single"``
      (``--no-shear-search``: one detection pass, the paper's).
    * ``min_confidence``: refuse estimates below this confidence, 0 to 1 (default 0.25).
    * ``max_shear``: refuse estimates whose ``|k|`` is beyond this, above 0 and at most 2
      (default 0.6; ``--max-shear``): usable photos' rolling-shutter shears stay well below.
    * ``max_crops``: most crops the network reads per face, 1 to 64 (default ``None``: 8 for
      stills, stopping when the estimate settles; 2 for video) (``--max-crops``).
    * ``refinements``: filters only: locate again in the de-sheared face (``--refinements``, 0).
    * ``shear_model``: filters only: ``"equation5"``, ``"shear-roll"`` or ``"shear-roll-yaw"``
      (default ``None``: shear-roll-yaw for stills, equation5 for video).
    * ``filter_type``: the built-in filter set, ``"mosse"`` (default), ``"asef"``, ``"umace"``.
    * ``min_face``: smallest face box in pixels (default ``None``: 40 for the network
      detector, the cascade's 20 px window for Viola-Jones); larger is faster.
    * ``min_neighbors`` (3) and ``scale_factor`` (1.1): the detector's OpenCV parameters.
    * ``proposals``: the thorough search's face proposals (default ``True``; ``--no-proposals``).
    * ``fallback_cascade``: also ask OpenCV's ``frontalface_default`` (default ``False``).
    * ``search_every_view``: with ``search="quick"``, search every view of every image.
    * ``shear_hypotheses`` / ``roll_hypotheses``: the de-sheared views' shears and the turned
      views' rolls in degrees (default ``None``: the search's own).
    * ``ruler``: what makes ``k``: ``"auto"`` (the stills' default) the faces (the scene's
      verticals read and reported only when no face gives ``k``); ``"combine"`` combines the two when they agree;
      ``"scene"`` also takes the scene's shear when no face gives one; ``"faces"`` (video's
      default) reads the faces alone.

    ``max_pixels`` bounds the images accepted (default 250,000,000). Bad settings raise
    ``ValueError`` naming the setting and its range for bad values (out of range, negative or
    too large integers, NaN or infinite numbers) or ``TypeError`` for unknown names and wrong
    types (a float or ``bool`` for an integer, ``bool`` or a string for a number).
    """

    def __new__(
        cls,
        *,
        max_pixels: int = ...,
        detector: Detector | None = None,
        locator: Locator = "network",
        search: Search | None = None,
        min_confidence: float = 0.25,
        max_shear: float = 0.6,
        max_crops: int | None = None,
        refinements: int = 0,
        shear_model: ShearModel | None = None,
        filter_type: FilterType = "mosse",
        min_face: int | None = None,
        min_neighbors: int = 3,
        scale_factor: float = 1.1,
        proposals: bool = True,
        fallback_cascade: bool = False,
        search_every_view: bool = False,
        shear_hypotheses: Iterable[float] | None = None,
        roll_hypotheses: Iterable[float] | None = None,
        ruler: Literal["faces", "auto", "combine", "scene"] | None = None,
    ) -> Unshear: ...
    @property
    def config(self) -> dict[str, Any]:
        """The settings, as keyword arguments of ``Unshear(**config)``."""
    @property
    def max_pixels(self) -> int:
        """The largest image accepted, in pixels."""
    def estimate(self, image: ImageLike, *, bgr: bool = False) -> Report:
        """Finds the faces in ``image`` and estimates the shear from each.

        Raises ``ValueError`` for an array that is not an image (wrong dtype, shape or channel
        count, empty, over ``max_pixels``) and ``TypeError`` for a non-array.
        """
    def estimate_many(
        self, images: Iterable[ImageLike], *, threads: int | None = None, bgr: bool = False
    ) -> list[Report]:
        """``estimate`` on every image, in parallel on ``threads`` threads (1 to 65535; default:
        one per core); the reports come back in the images' order. Every image is copied first,
        so memory grows with the batch."""
    def correct(
        self,
        image: ImageLike,
        k: float | None = None,
        *,
        region: Region = "image",
        canvas: Canvas = "same",
        interp: Interp = "linear",
        report: Report | None = None,
        bgr: bool = False,
        blur: float | Literal["auto"] | None = None,
    ) -> Image:
        """Removes the shear from ``image`` and returns a new array of its layout and dtype.

        The shear is ``k`` when given, otherwise ``report``'s (from ``estimate`` on this image,
        to avoid estimating twice), otherwise estimated here. ``region="image"`` de-shears the
        whole image about its middle row (each row by its own offset when the report's
        ``k_rows`` says the shear changes down the rows and no ``k`` is given); ``"face"`` each
        face region with its own shear.
        ``canvas``: ``"same"`` size, ``"expand"`` so nothing is cut off, or ``"crop"`` to valid
        pixels. ``interp``: ``"linear"`` or ``"cubic"``. ``blur``: a motion blur along the rows
        removed first, before the faces are read, its length in pixels (1 to 256) or ``"auto"``
        (found row by row from the zeros it leaves in the rows' spectrum, in bands of rows, as
        ``unshear correct --deblur``; none found, none removed).

        Raises ``NoFaceError`` (a ``ValueError``) when no face gave an accepted estimate and no
        ``k`` was given, ``ValueError`` for a NaN or infinite ``k`` or a bad ``blur``.
        """
    def estimate_file(self, path: PathLike) -> Report:
        """``estimate`` of an image file, as ``unshear estimate FILE`` reports it: a photo its
        EXIF orientation turns a quarter (a phone held upright) was read out column by column,
        and its shear is measured as the vertical one (``readout == "columns"``). Raises
        ``OSError`` as ``read``."""
    def correct_file(
        self,
        src: PathLike,
        dst: PathLike,
        k: float | None = None,
        *,
        region: Region = "image",
        canvas: Canvas = "same",
        interp: Interp = "linear",
        overwrite: bool = False,
        jpeg_quality: int = 95,
    ) -> Report:
        """Corrects the file ``src`` into ``dst`` (format from its extension) as ``unshear
        correct`` does, and returns the report it corrected by: the colour profile and EXIF
        block kept, ``dst`` written through a temporary file, never over ``src``, and an
        existing ``dst`` only with ``overwrite=True``. Options as ``correct``.

        A photo turned a quarter by its EXIF orientation is corrected along its columns (see
        ``Report.readout``), also by a given ``k``. Raises ``NoFaceError`` when there is nothing
        to correct by (no accepted estimate) and no ``k`` was given, with nothing written; ``FileExistsError`` for an existing ``dst`` or ``dst`` naming ``src``;
        ``OSError`` as ``read``; ``ValueError`` for an unsupported output format.
        """

@final
class Frame:
    """One frame out of a ``VideoCorrector``."""

    @property
    def image(self) -> Image:
        """The frame, corrected by ``k_applied`` (in the layout and dtype it was pushed in)."""
    @property
    def index(self) -> int:
        """The frame's number, from 0."""
    @property
    def k(self) -> float:
        """The frame's temporally filtered and smoothed shear."""
    @property
    def k_raw(self) -> float | None:
        """The frame's own estimate, ``None`` without a usable face."""
    @property
    def k_causal(self) -> float:
        """The causal filter's shear after this frame (from it and earlier frames only)."""
    @property
    def k_applied(self) -> float | None:
        """The shear the frame was corrected by; ``None`` with ``correct=False``."""
    @property
    def faces(self) -> list[Face]:
        """Every tracked face with an estimate."""
    @property
    def k_source(self) -> Literal["motion", "faces", "none"]:
        """Where ``k`` came from: the measured motion times the line time, the faces, or
        nothing (the last ``k`` held or decaying)."""
    @property
    def readout_fraction(self) -> float | None:
        """The readout fraction in use for this frame (given, or calibrated so far)."""
    @property
    def velocity(self) -> tuple[float, float] | None:
        """The image velocity ``(vx, vy)`` at the middle row's time, pixels per frame."""
    @property
    def blur(self) -> float | None:
        """The motion blur removed at the middle row, pixels (``deblur_exposure``)."""
    def to_dict(self) -> dict[str, Any]:
        """The frame's line of ``unshear video --json`` (``frame``, ``k_raw``, ``k``,
        ``k_source``, ``readout_fraction``, ``velocity``,
        ``faces``), not rounded."""

@final
class VideoCorrector:
    """A video stream corrected frame by frame, as ``unshear video`` does: faces tracked
    between full detections, ``k`` filtered over time and smoothed over ``smoothing_lag`` later
    frames.

    ``push(frame)`` returns the frame that is now due, ``smoothing_lag`` frames older, as a
    list of zero or one ``Frame``; ``finish()`` returns the frames still held.
    ``smoothing_lag=0`` returns every frame at once (the causal filter alone). Every frame must
    have the first one's size, channels and dtype. The settings of ``Unshear`` are accepted too
    (``max_crops`` defaults to 2 and ``shear_model`` to equation5 here, as for ``unshear
    video``).

    ``smoothing_lag`` is 0 to 250 frames (they are held in memory); ``redetect`` (default:
    5 with the network detector, 30 with Viola-Jones, as for ``unshear video``) and
    ``lost_interval`` are at least 1 frame; ``detect_width`` is in pixels (0: full size);
    ``fps`` and ``decay`` are above 0, ``hold`` at least 0 (seconds). Bad values raise
    ``ValueError`` and wrong types ``TypeError``, as for ``Unshear``.

    Once the readout fraction is known (``readout_fraction``, from a data sheet or ``unshear
    calibrate``; otherwise calibrated on the stream from its faces), each frame's ``k`` comes
    from the image motion measured between frames, ``k = readout_fraction * v / H``, with a
    per-row offset when the pan changes speed during the readout; ``motion=False`` keeps the
    faces alone, ``vertical=True`` also undoes vertical motion's stretch.
    ``deblur_exposure`` (each row's exposure over the frame interval, in (0, 1]; 4 ms at 30
    frames/s is 0.12; ``"auto"``: estimated from the blur once five frames moving fast enough
    showed one) also removes the motion blur along the rows of frames corrected from motion:
    each row's image velocity times the exposure.

    ``readout="columns"`` is for frames turned upright from a clip recorded turned a quarter
    (a phone held upright; OpenCV turns them so): read out along their columns, their ``k`` is
    the vertical shear ``y' = y + k x`` and they are corrected along their columns.
    """

    def __new__(
        cls,
        *,
        fps: float = 25.0,
        smoothing_lag: int = 6,
        redetect: int | None = None,
        lost_interval: int = 5,
        detect_width: int = 640,
        hold: float = 0.5,
        decay: float = 1.0,
        k_source: Literal["filtered", "raw"] = "filtered",
        readout: Literal["rows", "columns"] = "rows",
        interp: Interp = "linear",
        readout_fraction: float | None = None,
        motion: bool = True,
        vertical: bool = False,
        deblur_exposure: float | Literal["auto"] | None = None,
        correct: bool = True,
        bgr: bool = False,
        max_pixels: int = ...,
        detector: Detector | None = None,
        locator: Locator = "network",
        search: Search | None = None,
        min_confidence: float = 0.25,
        max_shear: float = 0.6,
        max_crops: int | None = None,
        refinements: int = 0,
        shear_model: ShearModel | None = None,
        filter_type: FilterType = "mosse",
        min_face: int | None = None,
        min_neighbors: int = 3,
        scale_factor: float = 1.1,
        proposals: bool = True,
        fallback_cascade: bool = False,
        search_every_view: bool = False,
        shear_hypotheses: Iterable[float] | None = None,
        roll_hypotheses: Iterable[float] | None = None,
        ruler: Literal["faces", "auto", "combine", "scene"] | None = None,
    ) -> VideoCorrector: ...
    @property
    def pending(self) -> int:
        """Frames pushed and not returned yet."""
    @property
    def smoothing_lag(self) -> int:
        """Each frame comes out this many pushes later."""
    def push(self, frame: ImageLike) -> list[Frame]:
        """Takes the next frame; returns the frame now due, corrected (zero or one)."""
    def finish(self) -> list[Frame]:
        """Ends the stream: every frame still held, corrected. Later pushes raise."""
    def analyse(self, frame: ImageLike) -> None:
        """First of two passes over a clip that can be read twice: analyses the next frame
        and keeps its results, not its pixels (instead of ``push``)."""
    def end_analysis(self) -> float | None:
        """Ends the first pass: returns the readout fraction fitted over the whole clip
        (``None`` when it could not be found; the frames are then corrected from their
        faces)."""
    def replay(self, frame: ImageLike) -> Frame:
        """Second pass: the next frame again, in order, corrected with what the first pass
        found."""

def options() -> list[dict[str, Any]]:
    """The settings ``Unshear(**config)`` and ``VideoCorrector(**config)`` take, one dict each:
    ``name``, ``kind`` (``"flag"``, ``"integer"``, ``"number"``, ``"numbers"`` or
    ``"choice"``), ``choices`` (the names of a choice, else empty), ``default`` and ``help``
    (text, as ``unshear --help`` gives them)."""

def read(path: PathLike, *, bgr: bool = False, max_pixels: int = ...) -> Image:
    """Reads an image file (JPEG, PNG, PNM, BMP, TIFF, WebP; the format from the content; the
    EXIF orientation applied; the size checked before decoding) into an array: H x W for grey,
    H x W x 2/3/4 otherwise, ``uint16`` for 16-bit files. Raises ``OSError`` (its subclasses
    ``FileNotFoundError``, ``PermissionError``, ...) with the reason."""

def write(
    path: PathLike,
    image: ImageLike,
    *,
    bgr: bool = False,
    overwrite: bool = True,
    jpeg_quality: int = 95,
) -> None:
    """Writes ``image`` to ``path``, its format from the extension (``.jpg``, ``.png``,
    ``.pgm``/``.ppm``, ``.bmp``, ``.tif``, ``.webp``), through a temporary file renamed into
    place. ``overwrite=False`` raises ``FileExistsError`` for an existing file. ``jpeg_quality``
    (1 to 100, else ``ValueError``) is the JPEG encoder's quality."""

def distort(
    image: ImageLike,
    k: float,
    *,
    pivot: float | None = None,
    canvas: Canvas = "same",
    interp: Interp = "linear",
) -> Image:
    """Applies a shear as a rolling shutter would: a point ``(x, y)`` moves to
    ``x + k (y - pivot)`` (``pivot`` default: the middle row, ``H / 2``). ``distort(image,
    -k)`` is ``Unshear.correct(image, k)``. A NaN or infinite ``k`` or ``pivot`` raises
    ``ValueError``."""
