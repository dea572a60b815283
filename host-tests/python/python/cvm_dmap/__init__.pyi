"""Type hints of cvm_dmap: the CVM defect scanner's numbers from NumPy
(dmap's and the firmware's own code). See docs/python.md."""

import os
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

_Path = Union[str, "os.PathLike[str]"]
_Scan = npt.NDArray[Any]

__version__: str
MAX_COLS: int

class DmapWarning(UserWarning):
    """What dmap prints as ``dmap: warning: ...``."""

class Calibration:
    """A calibration as ``dmap calibrate`` writes it (``text`` byte for byte)."""
    text: str
    json: Dict[str, Any]
    summary: str
    warnings: List[str]
    def __init__(self, text: str, summary: str = ..., warnings: Optional[List[str]] = ...) -> None: ...
    @classmethod
    def load(cls, path: _Path) -> "Calibration":
        """Reads a calibration file."""
    def save(self, path: _Path) -> None:
        """Writes the file ``dmap stream --calibration`` reads."""
    @property
    def thresholds(self) -> Dict[str, float]:
        """Per channel (cvm, power, spread), the threshold in its units."""
    @property
    def integers(self) -> Dict[str, int]:
        """Per channel, the integer the firmware compares with."""
    @property
    def rates(self) -> Dict[str, Optional[float]]:
        """Per channel, the estimated false positions per part."""
    @property
    def min_strength(self) -> Dict[str, Optional[float]]:
        """Per channel, the smallest rise above the median detected (None: nothing)."""

class Scan:
    """One decoded scan."""
    json: Dict[str, Any]
    header: Dict[str, Any]
    rows: int
    objects: List[Dict[str, Any]]
    defects: List[Dict[str, Any]]
    verdict: Optional[str]
    totals: Optional[Dict[str, Any]]
    problems: List[Dict[str, Any]]
    image: Optional[npt.NDArray[np.float64]]
    power_image: Optional[npt.NDArray[np.float64]]
    spread_image: Optional[npt.NDArray[np.float64]]
    image_refusal: Optional[str]

class Decoded:
    """A decoded stream (``json`` equals ``dmap listen --json``)."""
    json: Dict[str, Any]
    scans: List[Scan]
    problems: List[Dict[str, Any]]
    line_errors: List[Dict[str, Any]]
    damaged: bool
    damage: List[str]
    replies: int
    header: Optional[Dict[str, Any]]
    totals: Optional[Dict[str, Any]]
    verdict: Optional[str]
    objects: List[Dict[str, Any]]
    image: Optional[npt.NDArray[np.float64]]
    power_image: Optional[npt.NDArray[np.float64]]
    spread_image: Optional[npt.NDArray[np.float64]]

class StreamDamaged(ValueError):
    """A damaged stream (``dmap listen`` exits 1); ``result`` is the decode."""
    result: Decoded
    def __init__(self, message: str, result: Decoded) -> None: ...

class Metrics:
    """What ``dmap eval`` finds (``json`` equals ``dmap eval --json``)."""
    json: Dict[str, Any]
    snr: Optional[float]
    psnr: Optional[float]
    cnr: Optional[float]
    threshold: Optional[float]
    defects: List[Dict[str, Any]]
    objects: Dict[str, Any]
    mean_free: Optional[float]
    std_free: Optional[float]
    mean_defect: Optional[float]
    max_defect: Optional[float]
    n_free: int
    n_defect: int
    nan_free: int
    nan_defect: int
    rule: str

def score(scan: _Scan, distance: str = ..., *, kernels: Optional[str] = ..., weights: Optional[str] = ...,
          bmax: Optional[int] = ..., raw: bool = ..., ground: Optional[str] = ...) -> npt.NDArray[np.float64]:
    """The gradient image (rows, cols, 3) of a scan, bit for bit ``dmap score``'s."""

def score_many(scans: Sequence[_Scan], distance: str = ..., *, kernels: Optional[str] = ...,
               weights: Optional[str] = ..., bmax: Optional[int] = ..., raw: bool = ...,
               ground: Optional[str] = ...) -> List[npt.NDArray[np.float64]]:
    """:func:`score` of many scans, in parallel over the scans."""

def stream(scan: _Scan, settings: Optional[Dict[str, Any]] = ..., calibration: Union[None, Calibration, _Path] = ...,
           *, kernels: Optional[str] = ..., weights: Optional[str] = ..., bmax: Optional[int] = ...,
           raw: bool = ..., threshold: Optional[float] = ..., power_threshold: Optional[float] = ...,
           spread_threshold: Optional[float] = ..., scores: bool = ..., max_defect_lines: int = ...,
           full_scale: int = ...) -> bytes:
    """The firmware's result lines for a scan, byte for byte ``dmap stream``'s."""

def decode(lines: Union[bytes, bytearray, memoryview, str, Iterable[Union[bytes, str]]], *,
           pitch_um: Optional[float] = ..., max_scans: Optional[int] = ..., strict: bool = ...) -> Decoded:
    """``dmap listen``'s decoder; raises StreamDamaged on damage unless strict=False."""

def calibrate(scans: Sequence[Union[_Scan, _Path]], rate: Optional[float] = ..., rule: Optional[str] = ..., *,
              names: Optional[Sequence[str]] = ..., quantile: Optional[float] = ..., k: Optional[float] = ...,
              tail_fraction: Optional[float] = ..., kernels: Optional[str] = ..., weights: Optional[str] = ...,
              bmax: Optional[int] = ..., raw: bool = ..., full_scale: int = ...) -> Calibration:
    """The three channels' thresholds from defect-free references, as ``dmap calibrate``."""

def simulate(preset: str = ..., seed: int = ..., defects: Optional[Sequence[Tuple[str, Sequence[float]]]] = ..., *,
             defect_free: bool = ..., threads: Optional[int] = ...,
             **options: Any) -> Tuple[npt.NDArray[np.uint16], npt.NDArray[np.bool_]]:
    """(scan, truth) from the scanner's ray model, as ``dmap simulate``."""

def evaluate(grad: npt.NDArray[np.floating[Any]], truth: npt.NDArray[np.bool_], *, channel: int = ...,
             threshold: Optional[float] = ..., calibration: Union[None, Calibration, _Path] = ...,
             k: float = ..., dilate: int = ..., pitch_um: float = ...) -> Metrics:
    """SNR, PSNR, CNR, sizes and objects, as ``dmap eval --json``."""

eval = evaluate
