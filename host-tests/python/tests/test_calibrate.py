"""calibrate against dmap calibrate's file, byte for byte."""

import numpy as np
import pytest

import cvm_dmap


@pytest.mark.parametrize("kw,args", [
    ({}, []),
    ({"rate": 0.01}, ["--rate", "0.01"]),
    ({"rule": "spread", "k": 2.5, "quantile": 0.999}, ["--rule", "spread", "--k", "2.5", "--quantile", "0.999"]),
    ({"rate": 0.002, "tail_fraction": 0.05, "full_scale": 4095}, ["--rate", "0.002", "--tail-fraction", "0.05", "--full-scale", "4095"]),
    ({"kernels": "square", "bmax": 2}, ["--kernels", "square", "--bmax", "2"]),
])
def test_calibration_file_equals_dmap_byte_for_byte(dmap, files, tmp_path, kw, args):
    refs = [str(files / "ref1.npy"), str(files / "ref2.npy")]
    dmap.run("calibrate", *refs, *args, "-o", tmp_path / "cal.json")
    want = (tmp_path / "cal.json").read_bytes()
    from_paths = cvm_dmap.calibrate(refs, **kw)
    from_arrays = cvm_dmap.calibrate([np.load(r) for r in refs], names=refs, **kw)
    assert from_paths.text.encode() == want
    assert from_arrays.text.encode() == want
    from_arrays.save(tmp_path / "again.json")
    assert (tmp_path / "again.json").read_bytes() == want
    assert cvm_dmap.Calibration.load(tmp_path / "cal.json").json == from_arrays.json


def test_thresholds_rates_and_strengths_are_the_files(files):
    cal = cvm_dmap.calibrate([np.load(files / "ref1.npy"), np.load(files / "ref2.npy")])
    ch = cal.json["channels"]
    assert cal.thresholds == {c: ch[c]["threshold"] for c in ("cvm", "power", "spread")}
    assert cal.integers["cvm"] == ch["cvm"]["thr"]
    assert cal.rates["cvm"] == ch["cvm"]["false_positions_per_part"]
    assert cal.min_strength["power"] == ch["power"]["min_strength"]
    assert [r["file"] for r in cal.json["references"]] == ["scans[0]", "scans[1]"]
    assert cal.summary.startswith("dmap calibrate: ")


def test_two_calibration_targets_compare(files):
    refs = [np.load(files / "ref1.npy"), np.load(files / "ref2.npy")]
    strict = cvm_dmap.calibrate(refs, rate=0.0001)
    loose = cvm_dmap.calibrate(refs, rate=0.1)
    assert strict.thresholds["cvm"] >= loose.thresholds["cvm"]


def test_the_same_file_twice_is_refused_as_dmap_refuses_it(dmap, files, tmp_path):
    r = str(files / "ref1.npy")
    p = dmap.run("calibrate", r, r, "-o", tmp_path / "c.json", check=False)
    with pytest.raises(ValueError) as e:
        cvm_dmap.calibrate([r, r])
    assert p.returncode != 0
    assert str(e.value) == p.stderr.decode().strip().removeprefix("dmap: error: ")


def test_a_bad_rate_is_dmaps_message(dmap, files, tmp_path):
    r = str(files / "ref1.npy")
    p = dmap.run("calibrate", r, "--rate=-1.0", "-o", tmp_path / "c.json", check=False)
    with pytest.raises(ValueError) as e:
        cvm_dmap.calibrate([r], rate=-1.0)
    assert str(e.value) == p.stderr.decode().strip().removeprefix("dmap: error: ")
