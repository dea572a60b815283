"""Bad input raises a ValueError with a clear message, never crashes the
interpreter; random arrays and bytes (hypothesis) likewise."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import cvm_dmap

OK = np.ones((3, 4, 3, 3), np.uint16)


@pytest.mark.parametrize("scan,message", [
    (np.ones((3, 4, 3, 3), np.int16), r"^scan: unsupported dtype int16 \(scans must be uint8, uint16, uint32, float32 or float64\)$"),
    (np.ones((3, 4, 3, 3), np.complex64), "unsupported dtype complex64"),
    (np.ones((3, 4, 3, 3), np.bool_), "unsupported dtype bool"),
    (np.ones((3, 4, 9), np.uint16), r"^scan: a scan must have rank 4 \(rows, cols, J1, J2\), got shape \[3, 4, 9\] \(rank 3\)$"),
    (np.ones((2, 3, 4, 3, 3), np.uint16), "rank 5"),
    (np.ones((6, 4, 3, 3), np.uint16)[::2], "not C-contiguous"),
    (np.asfortranarray(np.ones((3, 4, 3, 3), np.uint16)), "not C-contiguous"),
    (np.ones((0, 4, 3, 3), np.uint16), r"^scan: empty scan \(shape \[0, 4, 3, 3\] has no beam positions\)$"),
    (np.ones((3, 4, 0, 3), np.uint16), "detector"),
    (np.ones((3, 4, 17, 3), np.uint16), "17"),
    ([[[[1]]]], "not a NumPy array but list"),
    ("scan.npy", "not a NumPy array but str"),
])
def test_a_bad_scan_is_a_value_error(scan, message):
    calls = [lambda s: cvm_dmap.score(s), lambda s: cvm_dmap.stream(s), lambda s: cvm_dmap.score_many([OK, s])]
    if not isinstance(scan, str):  # calibrate reads a str as a file's path
        calls.append(lambda s: cvm_dmap.calibrate([s]))
    for call in calls:
        with pytest.raises(ValueError, match=message.replace("^scan", "^(scan|scans\\[[01]\\])")):
            call(scan)


@pytest.mark.parametrize("value,what", [(np.nan, "NaN"), (np.inf, "inf"), (-1.0, "-1")])
def test_nan_infinite_or_negative_samples_are_named_by_position(value, what):
    scan = np.ones((3, 4, 3, 3))
    scan[2, 1, 0, 2] = value
    for distance in ("cvm", "cvm-fixed", "emd", "mean-dir"):
        with pytest.raises(ValueError, match=rf"^scan: sample {what} at position \(2, 1\) cell \(0, 2\) is not a finite non-negative intensity$"):
            cvm_dmap.score(scan, distance)


def test_a_scan_past_the_capacity_is_refused():
    wide = np.ones((1, cvm_dmap.MAX_COLS + 1, 1, 1), np.uint8)
    with pytest.raises(ValueError, match=rf"^scan has {cvm_dmap.MAX_COLS + 1} columns; the pipeline supports 1..={cvm_dmap.MAX_COLS}$"):
        cvm_dmap.stream(wide)


def test_bad_options_are_dmaps_messages():
    with pytest.raises(ValueError, match=r"invalid value 'cmv' for '--distance <DISTANCE>'"):
        cvm_dmap.score(OK, "cmv")
    with pytest.raises(ValueError, match="--raw applies only to the CVM distances"):
        cvm_dmap.score(OK, "emd", raw=True)
    with pytest.raises(ValueError, match="--ground applies only to --distance emd"):
        cvm_dmap.score(OK, ground="l1")
    with pytest.raises(ValueError, match="--bmax must be at least 1"):
        cvm_dmap.score(OK, bmax=0)
    with pytest.raises(ValueError, match="^--threshold must be a non-negative number, got -1$"):
        cvm_dmap.stream(OK, threshold=-1.0)
    with pytest.raises(ValueError, match="--threshold"):
        cvm_dmap.stream(OK, raw=True)


def test_a_clap_message_becomes_one_line_without_usage():
    # dmap prints clap's message over several lines with a usage and a
    # hint; the package raises its first lines joined, the rest dropped.
    with pytest.raises(ValueError) as e:
        cvm_dmap.score(OK, kernels="x")
    assert str(e.value) == "invalid value 'x' for '--kernels <KERNELS>' [possible values: paper, square]"


def test_a_damaged_stream_raises_with_the_decode(files):
    lines = cvm_dmap.stream(np.load(files / "part.npy"))
    damaged = lines.replace(b"R,", b"R;", 1)
    with pytest.raises(cvm_dmap.StreamDamaged, match=r"^the stream was damaged \(") as e:
        cvm_dmap.decode(damaged)
    assert e.value.result.damaged and e.value.result.line_errors
    with pytest.raises(cvm_dmap.StreamDamaged, match="damaged"):
        cvm_dmap.decode(lines[: len(lines) // 2])
    with pytest.raises(cvm_dmap.StreamDamaged):
        cvm_dmap.decode(b"")
    assert cvm_dmap.decode(b"", strict=False).scans == []


def test_options_take_numpy_scalars_and_refuse_nothing_to_calibrate(files):
    scan = np.load(files / "part.npy")
    assert cvm_dmap.stream(scan, threshold=np.float64(0.3), max_defect_lines=np.int64(2)) == cvm_dmap.stream(
        scan, threshold=0.3, max_defect_lines=2)
    with pytest.raises(ValueError, match="^no reference scan given$"):
        cvm_dmap.calibrate([])


def test_bad_eval_input():
    g = np.zeros((3, 4, 3))
    t = np.zeros((3, 4), bool)
    t[1, 1] = True
    with pytest.raises(ValueError, match=r"shape \(rows, cols, 3\)"):
        cvm_dmap.evaluate(np.zeros((3, 4)), t)
    with pytest.raises(ValueError, match="bool"):
        cvm_dmap.evaluate(g, t.astype(np.uint8))
    with pytest.raises(ValueError, match="is 3x5 but the scores are 3x4"):
        cvm_dmap.evaluate(g, np.zeros((3, 5), bool))
    with pytest.raises(ValueError, match="invalid value '3' for '--component"):
        cvm_dmap.evaluate(g, t, channel=3)
    with pytest.raises(ValueError, match="--pitch-um must be positive"):
        cvm_dmap.evaluate(g, t, pitch_um=0.0)


DTYPES = st.sampled_from([np.uint8, np.uint16, np.uint32, np.float32, np.float64, np.int32, np.int8, np.float16,
                         np.dtype(">u2"), np.dtype(">f8")])
SHAPES = hnp.array_shapes(min_dims=0, max_dims=5, min_side=0, max_side=5)


@pytest.mark.filterwarnings("ignore::cvm_dmap.DmapWarning")
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(a=hnp.arrays(DTYPES, SHAPES, elements=None), distance=st.sampled_from(["cvm", "cvm-fixed", "emd", "mean-dir"]),
       view=st.booleans())
def test_random_arrays_score_or_raise_value_error(a, distance, view):
    if view and a.ndim >= 1 and a.shape[0] > 1:
        a = a[::2]
    try:
        g = cvm_dmap.score(a, distance)
    except ValueError as e:
        assert str(e) and "\n" not in str(e)
        return
    assert g.shape == a.shape[:2] + (3,) and np.isfinite(g).all()


@pytest.mark.filterwarnings("ignore::cvm_dmap.DmapWarning")
@settings(max_examples=150, deadline=None)
@given(a=hnp.arrays(st.sampled_from([np.uint8, np.uint16, np.float64]), hnp.array_shapes(min_dims=4, max_dims=4, min_side=1, max_side=4)))
def test_random_scans_stream_and_decode_back(a):
    try:
        lines = cvm_dmap.stream(a)
    except ValueError as e:
        assert "\n" not in str(e)
        return
    d = cvm_dmap.decode(lines)
    assert len(d.scans) == 1 and d.scans[0].rows == a.shape[0]


@settings(max_examples=300, deadline=None)
@given(data=st.binary(max_size=600) | st.lists(st.sampled_from([b"H,", b"R,", b"O,", b"E,", b"*", b"\n", b"\r", b",", b"v=7", b"0", b"FFFF"])).map(b"".join))
def test_random_bytes_decode_or_raise_stream_damaged(data):
    try:
        d = cvm_dmap.decode(data)
    except cvm_dmap.StreamDamaged as e:
        assert e.result.damaged
        return
    assert not d.damaged


@settings(max_examples=60, deadline=None)
@given(data=st.binary(min_size=1, max_size=40), at=st.integers(min_value=0))
def test_damage_spliced_into_a_whole_stream_is_found_or_harmless(files, data, at):
    lines = cvm_dmap.stream(np.load(files / "part.npy")[:4])
    at %= len(lines)
    spliced = lines[:at] + data + lines[at:]
    d = cvm_dmap.decode(spliced, strict=False)
    assert isinstance(d.damaged, bool)
