"""Light fields: the contract every dataset's scenes meet, views held in memory, and reading and writing PNG files.

Views are float32 arrays (V, U, H, W) gray or (V, U, H, W, 3) RGB in [0, 1], where ``views[v, u]`` is the
view at angular row v, column u, so that ``views.reshape(V * U, H, W)[k]`` is view k (row-major).
Disparity is in px per view step, (H, W) float32; positive = closer than the focus plane (HCI's sign).
Which files hold a dataset's views and ground truth is its adapter's (lfbench.data.dataset): HCI's
reader is lfbench.data.hci, layouts named by a pattern lfbench.data.pattern.
"""

from __future__ import annotations

import contextlib
import io
import warnings
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

import numpy as np
from PIL import Image

from lfbench.utils.errors import DataError
from lfbench.utils.names import FileNames
from lfbench.utils.readfile import check_regular_file

__all__ = ["GRAY_WEIGHTS", "LOWRES", "HIGHRES", "MAX_PNG_PIXELS", "MAX_RESOLUTION_PX", "MAX_VIEW_PIXELS", "rgb_to_gray",
           "read_png", "read_rgb", "read_mask", "png_bytes", "LightField", "ArrayLightField", "Scene",
           "PNGScene", "Benchmark", "check_scene_names", "weighted_gray_views"]

GRAY_WEIGHTS = (0.299, 0.587, 0.114)
LOWRES, HIGHRES = "lowres", "highres"


def rgb_to_gray(rgb: np.ndarray) -> np.ndarray:
    """(..., 3) RGB in [0, 1] -> (...) gray = 0.299 R + 0.587 G + 0.114 B, float32."""
    r, g, b = GRAY_WEIGHTS
    out = rgb[..., 0] * r + rgb[..., 1] * g + rgb[..., 2] * b
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def weighted_gray_views(lf: LightField, weights: tuple[float, float, float] | None) -> np.ndarray:
    """(V, U, H, W) float32 gray views of ``lf`` with the RGB ``weights`` (a network's own preprocessing, e.g.
    OACC-Net's mean of R, G and B) when it has colour (``rgb_views``); otherwise, or for None, its gray views."""
    rgb = getattr(lf, "rgb_views", None)
    if weights is None or rgb is None:
        return lf.gray_views()
    r, g, b = (np.float32(w) for w in weights)
    views = rgb()
    return np.clip(views[..., 0] * r + views[..., 1] * g + views[..., 2] * b, 0.0, 1.0).astype(np.float32)


#: The largest light field lfbench reads: px per side of a view, and pixels of all views together (81 views of
#: 2574x2574 px); bounds checked before anything is allocated from a file's numbers.
MAX_RESOLUTION_PX = 16384
MAX_VIEW_PIXELS = 2**29
MAX_PNG_PIXELS = 2**27  # any PNG lfbench reads (the largest a dataset holds: 5120x5120 masks = 2**24.6)
_SIXTEEN_BIT = {"I;16", "I;16B", "I;16L", "I;16N", "I"}  # 16-bit gray PNG (Pillow's modes for it)


@contextlib.contextmanager
def _open_png(path: Path, what: str, size: tuple[int, int] | None, said: str = "expected") -> Iterator[Image.Image]:
    """The PNG opened lazily, its dimensions checked from the header before any pixel is decoded
    (against ``size`` (H, W) when given, else against MAX_PNG_PIXELS; ``said``: who expects that size, for
    the message). Errors name the file."""
    if path.exists():  # not a device or FIFO (a FIFO would block open); a missing file is reported below
        check_regular_file(path, what)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # our own limits apply
            with Image.open(path) as img:
                w, h = img.size
                if size is not None and (h, w) != tuple(size):
                    noun = "view" if what == "view image" else what
                    raise DataError(f"{noun} is {w}x{h}, {said} {size[1]}x{size[0]}", path)
                if w * h > MAX_PNG_PIXELS:
                    raise DataError(f"{what} is {w}x{h} px, more than lfbench reads ({MAX_PNG_PIXELS} px)", path)
                yield img
    except FileNotFoundError:
        raise DataError(f"missing {what}", path) from None
    except IsADirectoryError:
        raise DataError(f"{what} is a folder, expected a PNG file", path) from None
    except Image.DecompressionBombError:
        raise DataError(f"{what} is larger than lfbench reads ({MAX_PNG_PIXELS} px)", path) from None
    except (OSError, ValueError, SyntaxError) as exc:
        raise DataError(f"cannot read {what}: {' '.join(str(exc).split())[:120]}", path) from None


def _sixteen_bit(img: Image.Image, path: Path, what: str) -> np.ndarray:
    """A 16-bit gray PNG's pixels as uint16 (H, W)."""
    arr = np.asarray(img)
    if arr.dtype != np.uint16:
        if arr.size and (arr.min() < 0 or arr.max() > 65535):
            raise DataError(f"{what}: {img.mode} pixel values outside 0..65535 (not a 16-bit PNG)", path)
        arr = arr.astype(np.uint16)
    return arr


def read_png(path: Path, what: str = "image", mode: str | None = None,
             size: tuple[int, int] | None = None) -> np.ndarray:
    """A PNG's pixels as stored (uint8/uint16, (H, W) or (H, W, C)), converted to PIL ``mode`` if given.

    A 16-bit gray PNG converted to "L" or "RGB" is scaled by its bit depth (65535 -> 255), not
    clipped as Pillow does. ``size`` (H, W): the expected dimensions, checked before decoding.
    DataError naming the file ("missing <what>" / "cannot read <what>: ...") if it cannot be read.
    """
    with _open_png(path, what, size) as img:
        if img.mode in _SIXTEEN_BIT:
            arr = _sixteen_bit(img, path, what)
            if mode is None:
                return arr
            if mode not in ("L", "RGB"):
                raise DataError(f"cannot read {what}: a 16-bit gray PNG cannot be converted to {mode}", path)
            eight = ((arr.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)
            return eight if mode == "L" else np.repeat(eight[..., None], 3, axis=-1)
        return np.asarray(img.convert(mode) if mode else img)


def read_rgb(path: Path, size: tuple[int, int] | None = None, *, said: str = "expected") -> np.ndarray:
    """A PNG as float32 (H, W, 3) in [0, 1] (8-bit / 255, 16-bit gray / 65535); DataError naming the
    file if unreadable or not ``size`` (H, W) (``said``: who expects that size, for the message)."""
    with _open_png(path, "view image", size, said) as img:
        if img.mode in _SIXTEEN_BIT:
            gray = _sixteen_bit(img, path, "view image").astype(np.float32) / np.float32(65535.0)
            return np.repeat(gray[..., None], 3, axis=-1)
        return np.asarray(img.convert("RGB")).astype(np.float32) / np.float32(255.0)


def read_mask(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """A mask PNG as bool (H, W): True where any colour channel is non-zero (alpha ignored);
    ``size`` (H, W): the expected dimensions, checked before decoding."""
    arr = read_png(path, "mask", size=size)
    if arr.ndim == 3:
        arr = arr[..., :3].any(axis=-1) if arr.shape[2] >= 3 else arr[..., 0]
    return arr.astype(bool)


def png_bytes(array: np.ndarray) -> bytes:
    """``array`` (H, W) or (H, W, 3) uint8 encoded as a PNG (zlib level 6; the synthetic scenes' bytes)."""
    buf = io.BytesIO()
    Image.fromarray(array).save(buf, format="PNG", compress_level=6)
    return buf.getvalue()


class LightField:
    """Anything a method can run on: a name, gray views and, where known, ground truth."""

    name: str

    @property
    def angular_size(self) -> tuple[int, int]:
        """(V, U): rows and columns of the camera grid."""
        raise NotImplementedError

    def gray_views(self) -> np.ndarray:
        """(V, U, H, W) float32 gray in [0, 1]."""
        raise NotImplementedError

    @property
    def spatial_size(self) -> tuple[int, int]:
        """(H, W) of each view (and of a prediction for it), px."""
        return tuple(self.gray_views().shape[2:4])

    def center_view(self) -> np.ndarray:
        """(H, W, 3) RGB (or (H, W) gray when no colour is known), float32 in [0, 1]."""
        v, u = self.angular_size
        return self.gray_views()[v // 2, u // 2]

    def gt_disparity(self) -> np.ndarray | None:
        """(H, W) float32 ground-truth disparity at low resolution, or None."""
        return None


@dataclass
class ArrayLightField(LightField):
    """Views held in memory, e.g. from VIEWS.npy (H, W, 81) gray."""

    views: np.ndarray
    name: str = "array"
    gt: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.views.ndim != 4:
            raise ValueError(f"views must be (V, U, H, W), got {self.views.shape}")
        self.views = np.asarray(self.views, dtype=np.float32)

    @classmethod
    def from_channels(cls, stack: np.ndarray, name: str = "array", angular: int | None = None) -> ArrayLightField:
        """From (H, W, N) with channel k = view k of a square N = A x A grid."""
        if stack.ndim != 3:
            raise ValueError(f"expected (H, W, N) views, got shape {stack.shape}")
        n = stack.shape[2]
        a = angular or int(round(n**0.5))
        if a * a != n:
            raise ValueError(f"{n} channels is not a square angular grid")
        views = np.moveaxis(stack, 2, 0).reshape(a, a, *stack.shape[:2])
        return cls(views=views, name=name)

    @property
    def angular_size(self) -> tuple[int, int]:
        return self.views.shape[0], self.views.shape[1]

    def gray_views(self) -> np.ndarray:
        return self.views

    def gt_disparity(self) -> np.ndarray | None:
        return self.gt


class Scene(LightField):
    """A scene a dataset adapter opened: the contract evaluation, checking and training read, whatever stores
    its views. An adapter provides the views through one public method, :meth:`load_views` (and, where it can
    read the centre view alone more cheaply, :meth:`load_center_view`); the scene keeps what was loaded until
    :meth:`release_views` (evaluation and ``check-dataset`` release each scene once scored, so that memory
    holds one scene's views at a time). The ground truth may exist at several resolutions (``LOWRES``, and
    ``HIGHRES`` where a dataset has it); evaluation masks are named. Views stored as PNG files, one per view:
    :class:`PNGScene` (HCI: lfbench.data.hci.HCIScene; views named by a pattern: lfbench.data.pattern.PatternScene).

    ``path``: the folder (or file) it was opened from; ``category``: the category / split folder it was
    found in; ``params``: camera parameters with depth <-> disparity conversions where the dataset has them
    (None: the metrics that need them do not apply); ``invalid_area_file``: the file name, in a training run's
    ``data.invalid_area/<scene>/`` folder, of a mask of pixels training leaves out, where the layout has such
    masks (SubFocal's for HCI; None: none). A scene pickles as :meth:`reopen_args` (a scoring worker reopens it,
    never receives its loaded views).
    """

    path: Path
    category: str
    params: object | None = None
    invalid_area_file: str | None = None

    # -- views: what an adapter provides --------------------------------------------------------

    def load_views(self) -> np.ndarray:
        """The views read from storage: (V, U, H, W, 3) float32 RGB in [0, 1], or (V, U, H, W) float32 gray;
        ``[r, c]`` is the view at angular row r, column c. Called once until :meth:`release_views`."""
        raise NotImplementedError

    def load_center_view(self) -> np.ndarray:
        """The centre view read from storage ((H, W, 3) RGB or (H, W) gray float32 in [0, 1]); default: taken
        from :meth:`load_views` (override where one view can be read alone)."""
        v, u = self.angular_size
        return self.load_views()[v // 2, u // 2]

    def load_views_uint8(self) -> np.ndarray:
        """The views as stored 8-bit RGB (V, U, H, W, 3) uint8 (what training keeps in memory); default:
        :meth:`load_views` rounded to 1/255 steps (exact for views read from 8-bit files)."""
        views = self.load_views()
        if views.ndim == 4:
            views = np.repeat(views[..., None], 3, axis=-1)
        return np.round(np.clip(views, 0.0, 1.0) * np.float32(255.0)).astype(np.uint8)

    # -- views: what the benchmark reads (loaded once, kept until released) -----------------------

    def _loaded(self) -> np.ndarray:
        views = self.__dict__.get("_views")
        if views is None:
            views = self.__dict__["_views"] = self._checked_views(self.load_views())
        return views

    def _checked_views(self, views: np.ndarray) -> np.ndarray:
        """``views`` as float32, refused (DataError naming the scene's file) unless (V, U, H, W[, 3]) of this scene
        and finite (found by one read: their sum is NaN or infinite where a value is; views lie in [0, 1])."""
        views = np.asarray(views, dtype=np.float32)
        v, u = self.angular_size
        path = getattr(self, "path", None)
        if views.ndim not in (4, 5) or views.shape[:2] != (v, u) or (views.ndim == 5 and views.shape[4] != 3):
            raise DataError(f"{type(self).__name__}.load_views gave an array of shape {views.shape}, expected "
                            f"({v}, {u}, H, W, 3) or ({v}, {u}, H, W)", path)
        if not np.isfinite(views.sum(dtype=np.float64)):
            raise DataError(f"the views of scene {self.name!r} hold NaN or infinite values", path)
        return views

    def rgb_views(self) -> np.ndarray:
        """(V, U, H, W, 3) float32 RGB in [0, 1] (gray repeated where the scene has no colour)."""
        views = self._loaded()
        return np.repeat(views[..., None], 3, axis=-1) if views.ndim == 4 else views

    def gray_views(self) -> np.ndarray:
        gray = self.__dict__.get("_gray")
        if gray is None:
            views = self._loaded()
            gray = self.__dict__["_gray"] = views if views.ndim == 4 else rgb_to_gray(views)
        return gray

    def center_view(self) -> np.ndarray:
        views = self.__dict__.get("_views")
        if views is not None:
            v, u = self.angular_size
            return views[v // 2, u // 2]
        return self.load_center_view()

    def views_uint8(self) -> np.ndarray:
        """(V, U, H, W, 3) uint8 RGB: :meth:`load_views_uint8`, not kept (training holds its own copy)."""
        return self.load_views_uint8()

    def release_views(self) -> None:
        """Forget the loaded views (the next use reads them again): one scene in memory at a time."""
        self.__dict__.pop("_views", None)
        self.__dict__.pop("_gray", None)

    # -- the rest of the contract ---------------------------------------------------------------

    def __reduce__(self):
        return _reopen, (type(self), *self.reopen_args())

    def reopen_args(self) -> tuple:
        """The arguments ``type(self)(*args)`` reopens this scene with."""
        return self.path, self.category

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.category}/{self.name})"

    def has_gt(self, resolution: str = LOWRES) -> bool:
        """Whether ground truth exists at ``resolution``."""
        raise NotImplementedError

    def gt_disparity(self, resolution: str = LOWRES) -> np.ndarray | None:
        """Ground-truth disparity (H, W) float32 px per view step at ``resolution`` (H, W scaled), or None."""
        raise NotImplementedError

    def mask_names(self, resolution: str = LOWRES) -> list[str]:
        """Names of the evaluation masks present at ``resolution`` (none unless the layout has masks)."""
        return []

    def mask(self, name: str, resolution: str = LOWRES) -> np.ndarray:
        """Evaluation mask ``name`` at ``resolution`` as bool (H, W)."""
        raise DataError(f"this layout has no evaluation mask {name!r}", self.path)

    def valid_mask(self) -> np.ndarray | None:
        """Pixels that may be scored, bool (H, W) at low resolution, or None (all)."""
        return None


class PNGScene(Scene):
    """A scene whose views are PNG files, one per view (:meth:`view_file`), all ``spatial_size`` (H, W)."""

    spatial_size: tuple[int, int]
    #: who says the views are ``spatial_size``, for the message about a view of another size
    size_said: str = "expected"

    def view_file(self, row: int, col: int) -> Path:
        """The file of the view at 0-based angular ``row``, ``col``."""
        raise NotImplementedError

    def check_views(self) -> None:
        """Called before the views are read (e.g. a check that every file is there)."""

    def load_views(self) -> np.ndarray:
        self.check_views()
        v, u = self.angular_size
        h, w = self.spatial_size
        views = np.empty((v, u, h, w, 3), dtype=np.float32)
        for r in range(v):
            for c in range(u):
                views[r, c] = read_rgb(self.view_file(r, c), size=(h, w), said=self.size_said)
        return views

    def load_center_view(self) -> np.ndarray:
        v, u = self.angular_size
        return read_rgb(self.view_file(v // 2, u // 2), size=self.spatial_size, said=self.size_said)

    def load_views_uint8(self) -> np.ndarray:
        """Each PNG's pixels as 8-bit RGB (16-bit gray scaled by its bit depth: lfbench.data.scene.read_png)."""
        self.check_views()
        v, u = self.angular_size
        h, w = self.spatial_size
        out = np.empty((v, u, h, w, 3), dtype=np.uint8)
        for r in range(v):  # one file per view: reading is per file by nature
            for c in range(u):
                out[r, c] = read_png(self.view_file(r, c), "view image", "RGB", size=(h, w))
        return out


def _reopen(cls: type[Scene], *args: object) -> Scene:
    return cls(*args)


# --------------------------------------------------------------------------- a data root


@dataclass(frozen=True)
class Benchmark:
    """The scenes a dataset adapter found under a data root (lfbench.data.dataset.Dataset.open), each with
    the category (or split) folder it was found in.

    ``splits``: split name -> the categories it selects (a dataset with named splits of several category
    folders declares them, HCI: lfbench.data.hci.SPLITS; none where a dataset's category folders are its
    splits). ``others``: further roots whose scenes this one holds too (lfbench.data.dataset.open_datasets).
    """

    root: Path
    scenes: tuple[Scene, ...]
    splits: Mapping[str, tuple[str, ...]] = field(default_factory=dict, compare=False, hash=False)
    others: tuple[Path, ...] = ()

    @staticmethod
    def root_list(roots: str | Path | Iterable[str | Path] | None) -> list[Path]:
        """``roots`` (one data root, several, or None for none) as a list of paths."""
        if roots is None:
            return []
        return [Path(roots)] if isinstance(roots, str | Path) else [Path(r) for r in roots]

    @property
    def roots(self) -> tuple[Path, ...]:
        """Every data root this benchmark's scenes come from."""
        return (self.root, *self.others)

    def __iter__(self) -> Iterator[Scene]:
        return iter(self.scenes)

    def __len__(self) -> int:
        return len(self.scenes)

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.scenes]

    def by_category(self, *categories: str) -> list[Scene]:
        return [s for s in self.scenes if s.category in categories]

    def split(self, name: str) -> list[Scene]:
        """The scenes of split ``name`` (:attr:`splits`; HCI's: train = additional, validation = stratified +
        training, test = test)."""
        if name not in self.splits:
            raise DataError(f"unknown split {name!r}; choose from {', '.join(self.splits)}")
        return self.by_category(*self.splits[name])

    def select(self, names: list[str] | None) -> list[Scene]:
        """Scenes by name (or category name, or split name); all scenes when ``names`` is empty.
        DataError when two selected scenes share a name (:func:`check_scene_names`)."""
        if not names:
            return check_scene_names(self.scenes)
        out: list[Scene] = []
        for n in names:
            if n in self.splits:
                hits = self.split(n)
            else:
                hits = [s for s in self.scenes if n in (s.name, s.category)]
            if not hits:
                raise DataError(f"no scene {n!r}; available: {', '.join(self.names)}",
                                ", ".join(str(r) for r in self.roots))
            out += [s for s in hits if s not in out]
        return check_scene_names(out)

    def named(self, names: Iterable[str]) -> list[Scene]:
        """The scenes whose name is one of ``names`` (e.g. the scenes of a results file; absent ones are
        left out), refused as :meth:`select` refuses two of one name."""
        wanted = set(names)
        return check_scene_names([s for s in self.scenes if s.name in wanted])


SceneT = TypeVar("SceneT", bound=LightField)


def check_scene_names(scenes: Iterable[SceneT]) -> list[SceneT]:
    """``scenes`` as a list; DataError when two of them from different folders share a name (results,
    maps and figures name a scene by its name, so one would overwrite or merge with the other), or when
    two names are one file name (lfbench.utils.names: 'a<b' and 'a>b' are both 'a_b')."""
    scenes = list(scenes)
    first: dict[str, SceneT] = {}
    file_names = FileNames("scene")
    for scene in scenes:
        other = first.setdefault(scene.name, scene)
        path, other_path = getattr(scene, "path", None), getattr(other, "path", None)
        if other is not scene and path != other_path:
            raise DataError(f"two scenes are named {scene.name!r}: {other_path} and {path}; results name a scene by "
                            "its name, so select one of them by category (--scenes CATEGORY, or --data ROOT/CATEGORY) "
                            "or rename one folder")
        file_names(scene.name)
    return scenes
