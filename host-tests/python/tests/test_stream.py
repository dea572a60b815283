"""stream against dmap stream, decode against dmap listen, on the same
files and lines."""

import json

import numpy as np
import pytest

import cvm_dmap
from conftest import VECTORS


@pytest.mark.parametrize("kw,args", [
    ({}, []),
    ({"scores": True}, ["--scores"]),
    ({"threshold": 0.25, "power_threshold": float("inf")}, ["--threshold", "0.25", "--power-threshold", "inf"]),
    ({"spread_threshold": 0.05, "max_defect_lines": 3}, ["--spread-threshold", "0.05", "--max-defect-lines", "3"]),
    ({"full_scale": 4095, "kernels": "square", "scores": True}, ["--full-scale", "4095", "--kernels", "square", "--scores"]),
    ({"raw": True, "threshold": 4194304.0}, ["--raw", "--threshold", "4194304.0"]),
    ({"threshold": 0.0, "power_threshold": 0.0}, ["--threshold", "0", "--power-threshold", "0"]),
])
def test_stream_equals_dmap_byte_for_byte(dmap, files, kw, args):
    got = cvm_dmap.stream(np.load(files / "part.npy"), **kw)
    want = dmap.run("stream", files / "part.npy", *args).stdout
    assert isinstance(got, bytes) and len(got) > 0
    assert got == want


def test_settings_dict_is_the_keywords(files):
    scan = np.load(files / "part.npy")
    assert cvm_dmap.stream(scan, {"threshold": 0.3, "scores": True}) == cvm_dmap.stream(scan, threshold=0.3, scores=True)
    assert cvm_dmap.stream(scan, {"threshold": 0.3}, threshold=0.0) == cvm_dmap.stream(scan, threshold=0.0)
    with pytest.raises(ValueError, match="unknown setting 'treshold'"):
        cvm_dmap.stream(scan, {"treshold": 0.3})


def test_stream_with_a_calibration_object_or_file_equals_dmap(dmap, files, tmp_path):
    refs = [files / "ref1.npy", files / "ref2.npy"]
    cal_file = tmp_path / "cal.json"
    dmap.run("calibrate", *refs, "-o", cal_file)
    cal = cvm_dmap.calibrate([np.load(r) for r in refs], names=[str(r) for r in refs])
    scan = np.load(files / "part.npy")
    want = dmap.run("stream", files / "part.npy", "--calibration", cal_file, "--scores").stdout
    assert cvm_dmap.stream(scan, calibration=cal, scores=True) == want
    assert cvm_dmap.stream(scan, calibration=cal_file, scores=True) == want


def test_a_calibration_for_other_options_is_refused(files):
    cal = cvm_dmap.calibrate([np.load(files / "ref1.npy")], kernels="square")
    with pytest.raises(ValueError, match="calibrated for another scoring configuration"):
        cvm_dmap.stream(np.load(files / "part.npy"), calibration=cal)


@pytest.mark.parametrize("scores", [False, True])
def test_decode_equals_dmap_listen(dmap, files, tmp_path, scores):
    lines = dmap.run("stream", files / "part.npy", *(["--scores"] if scores else [])).stdout
    got = cvm_dmap.decode(lines, pitch_um=334)
    assert got.json == dmap.json("listen", "--input", "-", "--json", "--pitch-um", "334", input=lines)
    dmap.run("listen", "--input", "-", "-o", tmp_path / "s.npy", "--power-output", tmp_path / "p.npy", input=lines)
    assert got.image.tobytes() == np.load(tmp_path / "s.npy").tobytes()
    assert got.power_image.tobytes() == np.load(tmp_path / "p.npy").tobytes()
    assert got.spread_image.shape == got.image.shape
    assert got.verdict == got.totals["verdict"] and got.header["geometry"] == [9, 9]
    assert got.objects == got.scans[-1].objects and got.totals == got.scans[-1].totals


def test_a_cut_scan_has_no_image_as_dmap_listen_writes_none(files):
    lines = cvm_dmap.stream(np.load(files / "part.npy"), scores=True)
    cut = cvm_dmap.decode(lines[: len(lines) // 2], strict=False)
    assert cut.damaged and cut.image is None and cut.verdict is None
    assert cut.scans[0].image_refusal.startswith("has no end line (cut)")


def test_decode_takes_text_and_lists_of_lines(files):
    lines = cvm_dmap.stream(np.load(files / "part.npy"))
    want = cvm_dmap.decode(lines).json
    assert cvm_dmap.decode(lines.decode()).json == want
    assert cvm_dmap.decode(lines.splitlines(keepends=True)).json == want


def test_decode_of_the_score_lines_gives_the_fixed_point_magnitudes(files):
    scan = np.load(files / "part.npy")
    img = cvm_dmap.decode(cvm_dmap.stream(scan, scores=True)).image
    fixed = cvm_dmap.score(scan, "cvm-fixed")
    assert np.array_equal(img[..., 2], fixed[..., 2])


def vectors():
    return json.loads((VECTORS / "index.json").read_text())


def records(name):
    """The decoded records of a vector's lines (its NAME.jsonl): errors and
    empty lines left out."""
    lines = (VECTORS / f"{name}.jsonl").read_text().splitlines()
    return [d for d in map(json.loads, lines) if "type" in d]


@pytest.mark.parametrize("vector", vectors(), ids=lambda v: v["name"])
def test_every_conformance_vector_decodes_as_dmap_listen(dmap, vector):
    name, damage = vector["name"], vector["damage"]
    path = VECTORS / f"{name}.txt"
    data = path.read_bytes()
    if not damage:
        got = cvm_dmap.decode(data)
    else:
        with pytest.raises(cvm_dmap.StreamDamaged) as e:
            cvm_dmap.decode(data)
        assert str(e.value).startswith("the stream was damaged (")
        got = e.value.result
        assert got.json == cvm_dmap.decode(data, strict=False).json
    assert got.json == dmap.json("listen", "--input", path, "--json", check=False)
    assert got.damaged == bool(damage)
    assert sorted({p["kind"] for p in got.problems}) == damage
    # The scans' verdicts and totals are those of their end lines.
    ends = [r["fields"] for r in records(name) if r["type"] == "E"]
    if not damage:
        assert [s.json["totals"] for s in got.scans] == ends
        assert [s.verdict for s in got.scans] == [e["verdict"] for e in ends]
