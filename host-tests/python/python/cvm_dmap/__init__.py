"""The CVM defect scanner's numbers from NumPy.

Every function runs the code the firmware and the ``dmap`` host tool run
(the Rust crates of this repository, through ``cvm_dmap._native``), not a
second implementation: ``score`` equals ``dmap score`` bit for bit,
``stream`` the firmware's UART lines (``dmap stream``), ``decode`` is
``dmap listen``'s decoder, ``calibrate`` writes what ``dmap calibrate``
writes, ``simulate`` and ``evaluate`` are ``dmap simulate`` and ``dmap
eval``. Bad input raises ``ValueError`` with the one-line message ``dmap``
prints; what ``dmap`` prints as a warning is a :class:`DmapWarning`.
"""

import json
import os
import tempfile
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._options import DmapWarning, argv, scoring, warn
from ._results import Calibration, Decoded, Metrics, Scan, StreamDamaged

__all__ = [
    "score", "score_many", "stream", "decode", "calibrate", "simulate", "evaluate",
    "Calibration", "Decoded", "Scan", "Metrics", "StreamDamaged", "DmapWarning", "MAX_COLS",
]

try:
    from importlib.metadata import version as _version

    __version__: str = _version("cvm-dmap")
except Exception:  # not installed as a distribution (a source tree on sys.path)
    __version__ = "unknown"

#: Most columns a scan may have on the board (``dmap stream`` refuses more).
MAX_COLS: int = _native.MAX_COLS

Path = Union[str, "os.PathLike[str]"]


def score(scan: np.ndarray, distance: str = "cvm", *, kernels: Optional[str] = None,
          weights: Optional[str] = None, bmax: Optional[int] = None, raw: bool = False,
          ground: Optional[str] = None) -> np.ndarray:
    """The gradient image (Eq. 1) of a scan, as ``dmap score``.

    ``scan`` is a C-contiguous array ``(rows, cols, J1, J2)`` of uint8,
    uint16, uint32, float32 or float64, either byte order (read in place,
    not copied);
    ``distance`` one of ``"cvm"`` (exact, f64), ``"cvm-fixed"`` (the
    firmware's fixed point, which needs integer counts 0..65535), ``"emd"``
    or ``"mean-dir"``. ``kernels`` (``"paper"``, ``"square"``),
    ``weights`` (``"uniform"``, ``"unit"``), ``bmax`` and ``raw`` apply to
    the CVM distances, ``ground`` (``"euclid"``, ``"l1"``) to EMD. Returns
    float64 ``(rows, cols, 3)``: the horizontal and vertical gradients and
    the magnitude, equal bit for bit to ``dmap score -o``'s file. The GIL is
    released while it scores, on every core.
    """
    opts = argv({"distance": distance, **scoring(kernels, weights, bmax, raw), "ground": ground})
    out, warnings = _native.score(scan, opts)
    warn(warnings)
    return out


def score_many(scans: Sequence[np.ndarray], distance: str = "cvm", *, kernels: Optional[str] = None,
               weights: Optional[str] = None, bmax: Optional[int] = None, raw: bool = False,
               ground: Optional[str] = None) -> List[np.ndarray]:
    """:func:`score` of many scans (of any shapes), scored in parallel
    over the scans with the GIL released; one image per scan, in order.
    An error names the scan (``scans[3]: ...``)."""
    opts = argv({"distance": distance, **scoring(kernels, weights, bmax, raw), "ground": ground})
    outs, warnings = _native.score_many(list(scans), opts)
    for w in warnings:
        warn(w)
    return outs


def _calibration_arg(calibration: Union[None, Calibration, Path]) -> Tuple[Dict[str, Any], Optional[str]]:
    if calibration is None:
        return {}, None
    if isinstance(calibration, Calibration):
        return {"calibration": "calibration"}, calibration.text
    return {"calibration": os.fspath(calibration)}, None


def stream(scan: np.ndarray, settings: Optional[Dict[str, Any]] = None,
           calibration: Union[None, Calibration, Path] = None, *, kernels: Optional[str] = None,
           weights: Optional[str] = None, bmax: Optional[int] = None, raw: bool = False,
           threshold: Optional[float] = None, power_threshold: Optional[float] = None,
           spread_threshold: Optional[float] = None, scores: bool = False,
           max_defect_lines: int = 0, full_scale: int = 65535) -> bytes:
    """The firmware's result lines for a scan, as ``dmap stream`` prints
    them (and so as the board sends them): the header, each row's line, the
    defect objects, the verdict and totals.

    ``scan`` holds integer counts 0..65535 (any dtype ``score`` takes).
    ``calibration`` is a :class:`Calibration` or a calibration file's path
    (its thresholds, refused unless made for these scoring options);
    otherwise ``threshold`` (distance units, default 0.5),
    ``power_threshold`` (a contrast, default 0.1; ``math.inf`` off) and
    ``spread_threshold`` (default off). ``scores`` adds every position's S
    line, ``max_defect_lines`` up to that many D lines per row,
    ``full_scale`` the detector's full scale. ``settings`` is a dict of
    these same keyword arguments (the keywords win).
    """
    opts: Dict[str, Any] = {
        **scoring(kernels, weights, bmax, raw), "threshold": threshold,
        "power_threshold": power_threshold, "spread_threshold": spread_threshold,
        "scores": scores, "max_defect_lines": max_defect_lines or None,
        "full_scale": None if full_scale == 65535 else full_scale,
    }
    for k, v in (settings or {}).items():
        if k not in opts:
            raise ValueError(f"unknown setting {k!r} (one of {', '.join(sorted(opts))})")
        if opts[k] is None or opts[k] is False:
            opts[k] = v
    cal, text = _calibration_arg(calibration)
    lines, warnings = _native.stream(scan, argv({**opts, **cal}), text)
    warn(warnings)
    return lines


def decode(lines: Union[bytes, bytearray, memoryview, str, Iterable[Union[bytes, str]]], *,
           pitch_um: Optional[float] = None, max_scans: Optional[int] = None,
           strict: bool = True) -> Decoded:
    """Decodes result lines with ``dmap listen``'s decoder and every check
    it makes (CRCs, fields, order, cross-checks, cut lines).

    ``lines`` is the stream's bytes (or text, or an iterable of lines
    with their line ends). ``pitch_um`` adds sizes in mm to the objects.
    Returns a :class:`Decoded`, whose ``json`` equals ``dmap listen
    --json``'s document. A damaged stream (where ``dmap listen`` exits 1)
    raises :class:`StreamDamaged` (a ``ValueError``) carrying the whole
    decode in ``.result``, unless ``strict=False``.
    """
    if isinstance(lines, str):
        data = lines.encode("utf-8", "surrogateescape")
    elif isinstance(lines, (bytes, bytearray, memoryview)):
        data = bytes(lines)
    else:
        data = b"".join(l.encode("utf-8", "surrogateescape") if isinstance(l, str) else bytes(l) for l in lines)
    doc, images, damage = _native.decode(data, argv({"pitch_um": pitch_um, "max_scans": max_scans}))
    result = Decoded(json.loads(doc), images, damage)
    if damage and strict:
        raise StreamDamaged(f"the stream was damaged ({', '.join(damage)}; details in the result's problems)", result)
    return result


def calibrate(scans: Sequence[Union[np.ndarray, Path]], rate: Optional[float] = None,
              rule: Optional[str] = None, *, names: Optional[Sequence[str]] = None,
              quantile: Optional[float] = None, k: Optional[float] = None,
              tail_fraction: Optional[float] = None, kernels: Optional[str] = None,
              weights: Optional[str] = None, bmax: Optional[int] = None, raw: bool = False,
              full_scale: int = 65535) -> Calibration:
    """The three channels' thresholds from defect-free reference scans, as
    ``dmap calibrate``: the board's own calibrator, in its arithmetic.

    ``scans`` are arrays (integer counts) or ``.npy`` paths; ``names``
    name the arrays in the file and in messages (default ``scans[i]``; a
    path is its own name, as ``dmap calibrate`` records it). ``rule`` is
    ``"tail"`` (the board's default: ``rate`` false positions per part,
    default 0.001, ``tail_fraction``) or ``"spread"`` (``quantile``,
    ``k``). Returns a :class:`Calibration`; ``.save(path)`` writes the
    file ``dmap calibrate -o`` writes, byte for byte.
    """
    scans = list(scans)
    if not scans:
        raise ValueError("no reference scan given")
    if names is None:
        names = [os.fspath(s) if isinstance(s, (str, os.PathLike)) else f"scans[{i}]" for i, s in enumerate(scans)]
    refs = [os.fspath(s) if isinstance(s, os.PathLike) else s for s in scans]
    opts = {
        **scoring(kernels, weights, bmax, raw), "rule": rule, "rate": rate, "quantile": quantile,
        "k": k, "tail_fraction": tail_fraction, "full_scale": None if full_scale == 65535 else full_scale,
    }
    text, summary, warnings = _native.calibrate(refs, list(names), argv(opts))
    warn(warnings)
    return Calibration(text, summary, warnings)


def simulate(preset: str = "paper-sim", seed: int = 1,
             defects: Optional[Sequence[Tuple[str, Sequence[float]]]] = None, *,
             defect_free: bool = False, threads: Optional[int] = None,
             **options: Any) -> Tuple[np.ndarray, np.ndarray]:
    """A scan from the scanner's ray model, as ``dmap simulate``: returns
    ``(scan, truth)``, the scan uint16 ``(rows, cols, J1, J2)`` and the
    truth mask bool ``(rows, cols)``, the same numbers ``dmap simulate``
    writes for the same options (whatever the thread count).

    ``preset`` is ``"paper-sim"`` or ``"prototype"``; ``defects`` a list of
    ``("bubble", (x, y, z, r))``, ``("scratch", (x0, y0, x1, y1[, tilt]))``
    or ``("scatter", (x, y, size, share[, width]))`` (mm), each kind
    replacing the preset's defects of that kind; ``defect_free`` removes
    them all. Every other option of ``dmap simulate`` is a keyword, its
    name with ``_`` for ``-``: ``rows=40, cols=40, pitch_um=334,
    detector=(9, 9), photons=...``.
    """
    flags = {"bubble": "bubble", "scratch": "scratch", "scatter": "scatter"}
    opts: Dict[str, Any] = {"preset": preset, "seed": seed, "defect_free": defect_free, "threads": threads}
    if options.get("detector") is not None and not isinstance(options["detector"], str):
        options["detector"] = "x".join(str(d) for d in options["detector"])
    extra: List[str] = []
    for kind, values in defects or []:
        if kind not in flags:
            raise ValueError(f"unknown defect kind {kind!r} (bubble, scratch or scatter)")
        extra.append(f"--{flags[kind]}=" + ",".join(repr(float(v)) for v in values))
    scan, truth, _summary = _native.simulate(argv({**opts, **options}) + extra)
    return scan, truth


def evaluate(grad: np.ndarray, truth: np.ndarray, *, channel: int = 2, threshold: Optional[float] = None,
             calibration: Union[None, Calibration, Path] = None, k: float = 5.0, dilate: int = 2,
             pitch_um: float = 334.0) -> Metrics:
    """SNR, PSNR, CNR, defect sizes and objects of a gradient image
    against a truth mask, as ``dmap eval --json``.

    ``grad`` is float64 (or float32) ``(rows, cols, 3)``, ``truth`` bool
    ``(rows, cols)``; ``channel`` 0, 1 or 2 (the magnitude). The threshold
    is ``threshold``, else the CVM threshold of ``calibration``, else the
    defect-free mean + ``k`` standard deviations.
    """
    opts = {"channel": channel, "threshold": threshold, "k": k, "dilate": dilate, "pitch_um": pitch_um}
    if isinstance(calibration, Calibration):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "calibration.json")
            calibration.save(path)
            doc, extra = _native.eval(grad, truth, argv({**opts, "calibration": path}))
    else:
        doc, extra = _native.eval(grad, truth, argv({**opts, "calibration": calibration}))
    return Metrics(json.loads(doc), json.loads(extra))


#: :func:`evaluate` under the name of the ``dmap eval`` subcommand.
eval = evaluate  # noqa: A001
