"""What the functions return: a calibration, a decoded stream and its
scans, the evaluation metrics."""

import json
import os
from typing import Any, Dict, List, Optional, Union

import numpy as np

CHANNELS = ("cvm", "power", "spread")


class Calibration:
    """A calibration as ``dmap calibrate`` writes it.

    ``text`` is the file's text, byte for byte what ``dmap calibrate -o``
    writes for the same references and options; ``json`` the parsed
    document. Per channel (``"cvm"``, ``"power"``, ``"spread"``):
    ``thresholds`` (distance units, a contrast, a share of the power; a
    channel whose threshold is past every magnitude is off), ``integers``
    (the integers the firmware compares with), ``rates`` (the estimated
    false positions per part at the threshold) and ``min_strength`` (the
    smallest rise above the median the threshold detects, None when it
    detects nothing).
    """

    def __init__(self, text: str, summary: str = "", warnings: Optional[List[str]] = None):
        self.text = text
        self.json: Dict[str, Any] = json.loads(text)
        self.summary = summary
        self.warnings = list(warnings or [])

    @classmethod
    def load(cls, path: Union[str, "os.PathLike[str]"]) -> "Calibration":
        """Reads a calibration file (checked when it is applied)."""
        with open(path, encoding="utf-8-sig") as f:
            return cls(f.read())

    def save(self, path: Union[str, "os.PathLike[str]"]) -> None:
        """Writes the file ``dmap stream --calibration`` reads."""
        with open(path, "w", encoding="utf-8", newline="") as f:
            f.write(self.text)

    def _per_channel(self, key: str) -> Dict[str, Any]:
        ch = self.json.get("channels", {})
        return {c: ch[c].get(key) for c in CHANNELS if c in ch}

    @property
    def thresholds(self) -> Dict[str, float]:
        return self._per_channel("threshold")

    @property
    def integers(self) -> Dict[str, int]:
        return self._per_channel("thr")

    @property
    def rates(self) -> Dict[str, Optional[float]]:
        return self._per_channel("false_positions_per_part")

    @property
    def min_strength(self) -> Dict[str, Optional[float]]:
        return self._per_channel("min_strength")

    def __repr__(self) -> str:
        t = ", ".join(f"{c}={v!r}" for c, v in self.thresholds.items())
        return f"Calibration({t})"


class Scan:
    """One decoded scan: ``header`` (every header field), ``rows``,
    ``objects`` (the defect objects, as ``dmap listen --json``),
    ``defects`` (its D lines), ``verdict`` (None without an end line),
    ``totals``, ``problems``; and the images ``image`` (the CVM gradient
    magnitude), ``power_image`` and ``spread_image``, float64
    ``(rows, cols, 3)`` with the value in component 2 and NaN in
    components 0 and 1 and where nothing arrived. The images are None
    where ``dmap listen -o`` would not write one (``image_refusal`` says
    why: a scan without its end line, or claiming far more rows than
    arrived)."""

    def __init__(self, doc: Dict[str, Any], images: Any, refusal: Optional[str]):
        self.json = doc
        self.header: Dict[str, Any] = doc["header"]
        self.rows: int = doc["rows"]
        self.objects: List[Dict[str, Any]] = doc["objects"]
        self.defects: List[Dict[str, Any]] = doc["defects"]
        self.verdict: Optional[str] = doc["verdict"]
        self.totals: Optional[Dict[str, Any]] = doc["totals"]
        self.problems: List[Dict[str, Any]] = doc["problems"]
        self.image_refusal = refusal
        self.image: Optional[np.ndarray]
        self.power_image: Optional[np.ndarray]
        self.spread_image: Optional[np.ndarray]
        self.image, self.power_image, self.spread_image = images if images else (None, None, None)

    def __repr__(self) -> str:
        return f"Scan(rows={self.rows}, objects={len(self.objects)}, verdict={self.verdict!r})"


class Decoded:
    """A decoded stream of result lines. ``json`` is the document ``dmap
    listen --json`` prints for the same lines; ``scans`` each scan
    (:class:`Scan`); ``line_errors`` and ``problems`` the damage, each with
    ``scan``, ``line``, ``kind`` and ``what``; ``damaged`` whether
    ``dmap listen`` would exit 1. ``header``, ``totals``, ``verdict``,
    ``objects``, ``image``, ``power_image`` and ``spread_image`` are the
    last scan's (None, or empty, without a scan)."""

    def __init__(self, doc: Dict[str, Any], images: List[Any], damage: List[str]):
        self.json = doc
        self.scans = [Scan(s, im, why) for s, (im, why) in zip(doc["scans"], images)]
        self.problems: List[Dict[str, Any]] = doc["problems"]
        self.line_errors: List[Dict[str, Any]] = doc["line_errors"]
        self.damaged: bool = doc["damaged"]
        self.damage = damage
        self.replies: int = doc["replies"]
        last = self.scans[-1] if self.scans else None
        self.header = last.header if last else None
        self.totals = doc["totals"]
        self.verdict = doc["verdict"]
        self.objects = doc["objects"]
        self.image = last.image if last else None
        self.power_image = last.power_image if last else None
        self.spread_image = last.spread_image if last else None

    def __repr__(self) -> str:
        return f"Decoded(scans={len(self.scans)}, problems={len(self.problems)}, damaged={self.damaged})"


class StreamDamaged(ValueError):
    """A damaged stream of result lines (``dmap listen`` exits 1): the
    message is ``dmap listen``'s, ``result`` the whole decode."""

    def __init__(self, message: str, result: Decoded):
        super().__init__(message)
        self.result = result


class Metrics:
    """What ``dmap eval`` finds: ``snr``, ``psnr``, ``cnr`` (None when
    undefined), ``threshold``, ``defects`` (each truth defect's size,
    ``truth_mm`` and ``estimated_mm``), ``objects`` (truth and detected
    objects), ``json`` (the document ``dmap eval --json`` prints), and the
    statistics behind them: ``mean_free``, ``std_free``, ``mean_defect``,
    ``max_defect``, ``n_free``, ``n_defect``, ``nan_free``, ``nan_defect``
    and ``rule`` (how the threshold was chosen)."""

    def __init__(self, doc: Dict[str, Any], extra: Dict[str, Any]):
        self.json = doc
        self.snr = doc["snr"]
        self.psnr = doc["psnr"]
        self.cnr = doc["cnr"]
        self.threshold = doc["threshold"]
        self.defects = doc["defects"]
        self.objects = doc["objects"]
        self.mean_free = extra["mean_free"]
        self.std_free = extra["std_free"]
        self.mean_defect = extra["mean_defect"]
        self.max_defect = extra["max_defect"]
        self.n_free = extra["n_free"]
        self.n_defect = extra["n_defect"]
        self.nan_free = extra["nan_free"]
        self.nan_defect = extra["nan_defect"]
        self.rule = extra["rule"]

    def __repr__(self) -> str:
        return f"Metrics(snr={self.snr!r}, psnr={self.psnr!r}, cnr={self.cnr!r}, threshold={self.threshold!r})"
