"""simulate against dmap simulate, evaluate against dmap eval --json."""

import numpy as np
import pytest

import cvm_dmap


@pytest.mark.parametrize("kw,args", [
    ({"preset": "prototype", "seed": 5, "rows": 10, "cols": 12}, ["--preset", "prototype", "--seed", "5", "--rows", "10", "--cols", "12"]),
    ({"preset": "prototype", "seed": 2, "rows": 8, "cols": 9, "defect_free": True}, ["--preset", "prototype", "--seed", "2", "--rows", "8", "--cols", "9", "--defect-free"]),
    ({"preset": "paper-sim", "rows": 6, "cols": 7, "detector": (5, 7), "rays": 200, "center_mm": (-20.0, 10.0),
      "defects": [("bubble", (-20.0, 10.0, 2.0, 0.5))]},
     ["--rows", "6", "--cols", "7", "--detector", "5x7", "--rays", "200", "--center-mm=-20.0,10.0", "--bubble=-20.0,10.0,2.0,0.5"]),
])
def test_simulate_equals_dmap(dmap, tmp_path, kw, args):
    dmap.run("simulate", *args, "-o", tmp_path / "s.npy", "--truth", tmp_path / "t.npy")
    scan, truth = cvm_dmap.simulate(**kw)
    want, want_truth = np.load(tmp_path / "s.npy"), np.load(tmp_path / "t.npy")
    assert scan.dtype == want.dtype and scan.shape == want.shape
    assert np.array_equal(scan, want) and np.array_equal(truth, want_truth)


def test_simulate_refuses_bad_options_with_dmaps_message():
    with pytest.raises(ValueError, match="--power-rms-pct must be at least 0 and under 20"):
        cvm_dmap.simulate("prototype", rows=4, cols=4, power_rms_pct=30.0)
    with pytest.raises(ValueError, match="unexpected argument '--colour'"):
        cvm_dmap.simulate("prototype", colour=3)
    with pytest.raises(ValueError, match="unknown defect kind"):
        cvm_dmap.simulate("prototype", defects=[("crack", (0, 0, 0, 0))])


@pytest.mark.parametrize("kw,args", [
    ({}, []),
    ({"threshold": 0.9, "dilate": 0}, ["--threshold", "0.9", "--dilate", "0"]),
    ({"k": 3.0, "pitch_um": 100.0, "channel": 0}, ["--k", "3.0", "--pitch-um", "100.0", "--channel", "0"]),
])
@pytest.mark.parametrize("distance", ["cvm", "emd"])
def test_evaluate_equals_dmap_eval(dmap, files, tmp_path, distance, kw, args):
    g = tmp_path / "g.npy"
    dmap.run("score", files / "part.npy", "-o", g, "--distance", distance)
    want = dmap.json("eval", g, "--truth", files / "truth.npy", "--json", *args)
    m = cvm_dmap.evaluate(np.load(g), np.load(files / "truth.npy"), **kw)
    assert m.json == want
    assert (m.snr, m.psnr, m.cnr, m.threshold) == (want["snr"], want["psnr"], want["cnr"], want["threshold"])
    assert m.n_defect == int(np.load(files / "truth.npy").sum())


def test_evaluate_with_a_calibration_equals_dmap(dmap, files, tmp_path):
    g = tmp_path / "g.npy"
    dmap.run("score", files / "part.npy", "-o", g, "--distance", "cvm-fixed")
    dmap.run("calibrate", files / "ref1.npy", files / "ref2.npy", "-o", tmp_path / "cal.json")
    want = dmap.json("eval", g, "--truth", files / "truth.npy", "--json", "--calibration", tmp_path / "cal.json")
    cal = cvm_dmap.Calibration.load(tmp_path / "cal.json")
    assert cvm_dmap.evaluate(np.load(g), np.load(files / "truth.npy"), calibration=cal).json == want
    assert cvm_dmap.eval(np.load(g), np.load(files / "truth.npy"), calibration=tmp_path / "cal.json").json == want
