"""score and score_many against dmap score on the same files."""

import numpy as np
import pytest

import cvm_dmap

DISTANCES = ["cvm", "cvm-fixed", "emd", "mean-dir"]


def cli_score(dmap, tmp_path, scan_file, *args):
    out = tmp_path / "grad.npy"
    dmap.run("score", scan_file, "-o", out, *args)
    return np.load(out)


@pytest.mark.parametrize("distance", DISTANCES)
def test_each_distance_equals_dmap_bit_for_bit(dmap, files, tmp_path, distance):
    scan = np.load(files / "part.npy")
    got = cvm_dmap.score(scan, distance)
    want = cli_score(dmap, tmp_path, files / "part.npy", "--distance", distance)
    assert got.dtype == np.float64 and got.shape == (14, 16, 3)
    assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("kw,args", [
    ({"kernels": "square"}, ["--kernels", "square"]),
    ({"kernels": "square", "bmax": 3}, ["--kernels", "square", "--bmax", "3"]),
    ({"weights": "unit"}, ["--weights", "unit"]),
    ({"bmax": 2}, ["--bmax", "2"]),
    ({"raw": True}, ["--raw"]),
])
@pytest.mark.parametrize("distance", ["cvm", "cvm-fixed"])
def test_scoring_options_equal_dmap(dmap, files, tmp_path, distance, kw, args):
    scan = np.load(files / "part.npy")
    got = cvm_dmap.score(scan, distance, **kw)
    want = cli_score(dmap, tmp_path, files / "part.npy", "--distance", distance, *args)
    assert got.tobytes() == want.tobytes()


def test_emd_ground_l1_equals_dmap(dmap, files, tmp_path):
    got = cvm_dmap.score(np.load(files / "part.npy"), "emd", ground="l1")
    want = cli_score(dmap, tmp_path, files / "part.npy", "--distance", "emd", "--ground", "l1")
    assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("dtype", ["uint8", "uint32", "float32", "float64"])
@pytest.mark.parametrize("distance", ["cvm", "cvm-fixed"])
def test_every_dtype_a_scan_file_may_have(dmap, files, tmp_path, dtype, distance):
    f = files / f"part_{dtype}.npy"
    got = cvm_dmap.score(np.load(f), distance)
    want = cli_score(dmap, tmp_path, f, "--distance", distance)
    assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("dtype", [">u2", ">u4", ">f4", ">f8"])
@pytest.mark.parametrize("distance", ["cvm", "cvm-fixed"])
def test_the_other_byte_order_as_dmap_reads_it(dmap, files, tmp_path, dtype, distance):
    scan = np.load(files / "part.npy").astype(dtype)
    np.save(tmp_path / "big.npy", scan)
    got = cvm_dmap.score(scan, distance)
    want = cli_score(dmap, tmp_path, tmp_path / "big.npy", "--distance", distance)
    assert got.tobytes() == want.tobytes()
    assert cvm_dmap.stream(scan) == dmap.run("stream", tmp_path / "big.npy").stdout


def test_an_unaligned_scan_is_read_in_place(files):
    scan = np.load(files / "part.npy")
    buf = bytearray(scan.nbytes + 1)
    odd = np.frombuffer(buf, dtype=np.uint16, offset=1, count=scan.size).reshape(scan.shape)
    odd[...] = scan
    assert not odd.flags.aligned
    assert cvm_dmap.score(odd, "cvm-fixed").tobytes() == cvm_dmap.score(scan, "cvm-fixed").tobytes()


def test_a_memory_mapped_scan_is_read_in_place(dmap, files, tmp_path):
    scan = np.load(files / "part.npy", mmap_mode="r")
    got = cvm_dmap.score(scan, "cvm-fixed")
    want = cli_score(dmap, tmp_path, files / "part.npy", "--distance", "cvm-fixed")
    assert got.tobytes() == want.tobytes()


def test_score_many_equals_score_of_each(files):
    scans = [np.load(files / n) for n in ("part.npy", "ref1.npy", "ref2.npy", "part_float32.npy")]
    scans.append(scans[0][:5, :7].copy())
    many = cvm_dmap.score_many(scans, "cvm-fixed")
    assert len(many) == len(scans)
    for s, g in zip(scans, many):
        assert g.tobytes() == cvm_dmap.score(s, "cvm-fixed").tobytes()


def test_score_many_names_the_scan_that_fails(files):
    good = np.load(files / "part.npy")
    bad = good.astype(np.float64) + 0.5
    with pytest.raises(ValueError, match=r"^scans\[1\]: float64 scan value 0?\.?\d*\.5 at"):
        cvm_dmap.score_many([good, bad], "cvm-fixed")


def test_fixed_point_refuses_what_is_not_a_count_as_dmap_does(dmap, files, tmp_path):
    scan = np.load(files / "part_halves.npy")
    with pytest.raises(ValueError) as e:
        cvm_dmap.score(scan, "cvm-fixed")
    p = dmap.run("score", files / "part_halves.npy", "-o", tmp_path / "x.npy", "--distance", "cvm-fixed", check=False)
    cli = p.stderr.decode().strip().removeprefix("dmap: error: ")
    assert p.returncode == 1
    assert str(e.value) == cli.replace(str(files / "part_halves.npy"), "scan")


def test_dmap_warnings_become_python_warnings():
    scan = np.ones((3, 4, 1, 2), np.uint16)
    with pytest.warns(cvm_dmap.DmapWarning, match="^1x2 maps: this configuration scores every pair of maps 0"):
        cvm_dmap.score(scan)


def test_a_scan_of_many_bands_equals_dmap(dmap, tmp_path):
    # 16x16 maps, 300 columns: dmap scores 13 rows a band, so 40 rows are 4 bands.
    scan = np.random.default_rng(7).integers(0, 4096, size=(40, 300, 16, 16), dtype=np.uint16)
    np.save(tmp_path / "wide.npy", scan)
    for distance in ("cvm", "cvm-fixed"):
        got = cvm_dmap.score(scan, distance)
        want = cli_score(dmap, tmp_path, tmp_path / "wide.npy", "--distance", distance)
        assert got.tobytes() == want.tobytes()


def test_the_gil_is_released_while_scoring():
    import threading
    import time

    scan = np.random.default_rng(1).integers(0, 4096, size=(150, 150, 15, 15), dtype=np.uint16)
    started, took = threading.Event(), []

    def work():
        started.set()
        t0 = time.perf_counter()
        cvm_dmap.score(scan, "cvm")
        took.append(time.perf_counter() - t0)

    t = threading.Thread(target=work)
    t.start()
    started.wait()
    last, gap = time.perf_counter(), 0.0
    while t.is_alive():
        now = time.perf_counter()
        gap, last = max(gap, now - last), now
    t.join()
    # With the GIL held through the call, this loop would stop for all of it.
    assert took[0] > 0.05
    assert gap < 0.5 * took[0], (gap, took[0])
