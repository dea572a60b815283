"""Shared fixtures: the dmap binary the package is compared with, and a
few small scans it simulates (so every comparison reads the same files)."""

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

HOST = Path(__file__).resolve().parents[2]
REPO = HOST.parent
VECTORS = REPO / "docs" / "protocol" / "vectors"


def dmap_binary() -> str:
    path = os.environ.get("DMAP") or str(HOST / "target" / "x86_64-unknown-linux-gnu" / "release" / "dmap")
    if not os.access(path, os.X_OK):
        pytest.exit(f"no dmap binary at {path}: build it (cargo build --release -p dmap) or set DMAP", 2)
    return path


class Dmap:
    """Runs the dmap binary."""

    def __init__(self, path: str):
        self.path = path

    def run(self, *args, input=None, check=True):
        p = subprocess.run([self.path, *map(str, args)], input=input, capture_output=True)
        if check and p.returncode != 0:
            raise AssertionError(f"dmap {' '.join(map(str, args))} failed: {p.stderr.decode()}")
        return p

    def json(self, *args, input=None, check=True):
        return json.loads(self.run(*args, input=input, check=check).stdout)


@pytest.fixture(scope="session")
def dmap():
    return Dmap(dmap_binary())


@pytest.fixture(scope="session")
def files(tmp_path_factory, dmap):
    """Small scans written by dmap simulate: a part with defects (and its
    truth), two defect-free references, and the same scan in every dtype
    a scan file may have."""
    d = tmp_path_factory.mktemp("scans")
    dmap.run("simulate", "--preset", "prototype", "--rows", 14, "--cols", 16, "--seed", 3,
             "-o", d / "part.npy", "--truth", d / "truth.npy")
    for i in (1, 2):
        dmap.run("simulate", "--preset", "prototype", "--rows", 14, "--cols", 16, "--seed", 10 + i,
                 "--defect-free", "-o", d / f"ref{i}.npy", "--truth", d / f"ref{i}.truth.npy")
    part = np.load(d / "part.npy")
    for dt in ("uint8", "uint32", "float32", "float64"):
        a = (part // 16).astype(dt) if dt == "uint8" else part.astype(dt)
        np.save(d / f"part_{dt}.npy", a)
    np.save(d / "part_halves.npy", part.astype(np.float64) / 2)
    return d
