"""Compressed precomputed light-transport matrices from Python.

``T`` has one row per pixel (or texel) and one column per light, a cubemap
texel of ``6·n²``; the image under lighting ``L`` is ``T·L``. ``ltm``
compresses ``T`` (``compress``), opens the ``.ltm`` files (``open``), and
relights images from them (``File.relighter``), with numpy arrays in and
out. Long work runs with the interpreter released, so other threads keep
running (and several threads may relight one file at once).

Errors: ``ValueError`` for bad input (dtype, shape, NaN, out-of-range
settings, corrupt files), ``OSError`` (and its ``FileNotFoundError`` and
``PermissionError``) for I/O, ``MemoryError`` when a buffer sized from a
file or argument would exceed the memory budget; each carries the Rust
library's message.
"""

import os
from typing import Callable, Literal, Optional, Tuple, TypedDict, Union

import numpy as np
import numpy.typing as npt

__version__: str
"""The crate's version (python/Cargo.toml, equal to the workspace's)."""

DEFAULT_WAVELET_TERMS: int
"""Wavelet lights per frame when ``terms`` is not given (200)."""

PathLike = Union[str, "os.PathLike[str]"]
Size = Union[int, str]
"""A number of bytes, or a size such as ``"512M"`` or ``"1.5G"`` (binary units)."""

Light = Union[PathLike, npt.NDArray[np.float32], npt.NDArray[np.float64]]
"""Lighting: a lat-long map as an ``(H, 2·H, 3)`` array or an EXR/HDR path
(resampled to the matrix's cubemap, optionally rotated), or a cubemap as a
``(6, n, n, 3)`` or ``(6·n², 3)`` array in column order
``j = face·n² + row·n + col`` (docs/FORMAT.md)."""

Rotation = Tuple[float, float, float]
"""Yaw, pitch, roll in degrees, as ``ltm relight --rotate``."""

Progress = Callable[[str, int, int], object]
"""Called as ``progress(stage, done, total)`` at most every 50 ms and at
each stage's end (stages: "import", "rows", "analysis", "coding", "fit",
"bake", "reference"). An exception it raises is raised again when the
operation ends; it does not stop the operation."""

class Dims(TypedDict):
    width: int
    height: int
    rows: int
    face_res: int
    lights: int
    channels: int
    layout: Literal["image", "texture"]

class FrameStats(TypedDict):
    frame_ms: float
    light_transform_ms: float
    selection_ms: float
    multiply_ms: float
    inverse_ms: float
    decode_ms: float
    columns_decoded: int
    lights: int
    nonzeros: int

class File:
    """An opened, validated ``.ltm`` file (from ``ltm.open``)."""

    @property
    def dims(self) -> Dims: ...
    @property
    def mode(self) -> Literal["2d", "4d", "adaptive", "pca"]: ...
    @property
    def error(self) -> float:
        """Measured relative L2 error of the whole decoded matrix."""
    @property
    def size(self) -> int:
        """The file's size in bytes."""
    @property
    def shape(self) -> Tuple[int, ...]:
        """The shape ``export()`` returns: ``(P, M)`` or ``(P, M, C)``."""
    @property
    def meta(self) -> dict:
        """The header as a dict: mode, row_filter, col_filter, bits, seed,
        target_error, achieved_error, keep, file_bytes, raw_bytes,
        has_albedo, pca_rank, surface_rows, dims."""
    def export(self) -> npt.NDArray[np.float32]:
        """The decoded matrix, float32, in the layout of ``ltm export``:
        ``(P, M)`` or ``(P, M, C)``, rows = pixels (row-major), columns =
        cubemap texels. MemoryError when it exceeds the memory budget."""
    def relighter(self, preload: bool = False) -> "Relighter":
        """A relighter for this file, charged to the same memory budget;
        ``preload`` decodes every column now rather than on first use."""

class Relighter:
    """Relights one file; thread-safe (each call uses a frame of its own)."""

    @property
    def size(self) -> Tuple[int, int]:
        """Width and height of the relit image."""
    @property
    def face_res(self) -> int:
        """The cubemap face resolution n: lighting has 6·n² texels."""
    @property
    def max_terms(self) -> int: ...
    @property
    def term_basis(self) -> Literal["wavelet", "linear"]: ...
    def preload(self) -> None:
        """Decodes every column now, so that frames only relight."""
    def cubemap(
        self, light: Light, rotation: Optional[Rotation] = None
    ) -> npt.NDArray[np.float32]:
        """The lighting as this file's ``(6·n², 3)`` cubemap."""
    def relight(
        self,
        light: Light,
        terms: Union[int, Literal["all"], None] = None,
        weighting: Literal["unweighted", "transport", "area"] = "unweighted",
        rotation: Optional[Rotation] = None,
    ) -> Tuple[npt.NDArray[np.float32], FrameStats]:
        """Relights under ``light``: an ``(H, W, 3)`` float32 image (bit for
        bit ``ltm relight``'s) and the frame's stats. ``terms``: wavelet
        lights per frame (default 200; more than the lights uses them all)
        or, for a pca file, the first principal components (default all)."""
    def render(
        self,
        light: Light,
        camera: Tuple[float, float, float],
        target: Tuple[float, float, float],
        up: Tuple[float, float, float] = (0.0, 1.0, 0.0),
        fov: float = 35.0,
        size: Tuple[int, int] = (512, 512),
        supersample: int = 3,
        terms: Union[int, Literal["all"], None] = None,
        weighting: Literal["unweighted", "transport", "area"] = "unweighted",
        rotation: Optional[Rotation] = None,
    ) -> Tuple[npt.NDArray[np.float32], FrameStats]:
        """Texture-space files: relights the texture, then draws the mesh
        from ``camera`` looking at ``target`` (``ltm render``): an
        ``(height, width, 3)`` view and the relight's stats."""

def open(source: Union[PathLike, bytes], max_memory: Optional[Size] = None) -> File:
    """Opens and validates an ``.ltm`` file from a path (memory-mapped) or
    its bytes. ``max_memory`` is the budget every buffer sized from the
    file is charged to (default: 75 % of the memory available)."""

def compress(
    matrix: Union[PathLike, npt.NDArray[np.float32], npt.NDArray[np.float64]],
    out: Optional[PathLike] = None,
    *,
    width: Optional[int] = None,
    height: Optional[int] = None,
    albedo: Optional[npt.NDArray[np.floating]] = None,
    mode: Literal["2d", "4d", "adaptive", "pca"] = "adaptive",
    max_error: Optional[float] = None,
    bits: Optional[int] = None,
    quantizer: Literal["uniform", "peak"] = "uniform",
    keep: Optional[int] = None,
    rank: Optional[int] = None,
    max_rank: Optional[int] = None,
    row_filter: str = "haar",
    col_filter: str = "legall53",
    entropy: Optional[Literal["range", "zstd"]] = None,
    near_error: Optional[float] = None,
    seed: int = 0x6C746D00,
    mem_budget: Optional[int] = None,
    progress: Optional[Progress] = None,
) -> Union[bytes, dict]:
    """Compresses a matrix as ``ltm compress`` does (same options and
    defaults: max_error 0.01, the uniform quantizer at 16 bits (``peak``:
    bits 10, raised while the target is missed);
    for pca without ``max_rank``, the fit's rank doubled from 256 up to the
    full rank while the target is missed).

    ``matrix``: a raw store path (from ``bake``), or a float32/float64 array
    of shape ``(P, M)`` or ``(P, M, C)``: P = width·height pixels
    (row-major; width and height default to the square root of P), M = 6·n²
    cubemap texels, C = 1 or 3, every value finite as float32 (checked as
    ``ltm import`` checks a ``.npy``). ``albedo``: ``(P, 3)`` or
    ``(H, W, 3)``, with a grey ``(P, M)`` matrix.

    ``near_error``: the relative L2 error of a store's near-field rows (a
    bake with a ``[light_plane]``), as ``--near-error``: None takes
    ``max_error`` (lossless with ``keep``), 0 keeps them losslessly.

    Returns the file's bytes when ``out`` is None; else writes ``out``
    (atomically) and returns the stats (file_bytes, raw_bytes,
    achieved_error, bits, target_met, and nonzeros, codings,
    near_field_bytes and near_field_error, or rank and predicted_error for
    pca)."""

def bake(
    scene: PathLike,
    out: PathLike,
    *,
    width: Optional[int] = None,
    height: Optional[int] = None,
    face_res: Optional[int] = None,
    texel_samples: Optional[int] = None,
    spp: Optional[int] = None,
    progress: Optional[Progress] = None,
) -> dict:
    """Ray-traces a scene description (TOML) to a raw store, as ``ltm
    bake`` (the keyword arguments override the scene file). Returns the
    report: path, rows_baked, blocks_total, blocks_resumed, resume,
    shadow_rays, seconds, dims."""

def reference(
    raw: PathLike,
    light: Light,
    rotation: Optional[Rotation] = None,
    max_memory: Optional[Size] = None,
    progress: Optional[Progress] = None,
) -> npt.NDArray[np.float32]:
    """The exact relit image ``T·L`` of a raw store (accumulated in double
    precision, times the albedo for a grey store), as ``ltm reference``."""

def read_exr(path: PathLike) -> npt.NDArray[np.float32]:
    """An OpenEXR file's first RGB layer as an ``(H, W, 3)`` float32 array
    (e.g. what ``ltm relight -o`` or ``ltm reference -o`` wrote)."""

def write_exr(path: PathLike, image: npt.NDArray[np.floating]) -> None:
    """Writes an ``(H, W, 3)`` array as a lossless 32-bit float RGB OpenEXR
    file, atomically (e.g. an environment map for the CLI)."""
