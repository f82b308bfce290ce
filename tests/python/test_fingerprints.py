"""The TOD fingerprints (tools/tod_fingerprint.py: every kernel path of every backend present, TOD,
adjoint, diagonal and normal maps) compared bit for bit where the engine promises the same bits: a
recording on other numbers of host threads (cpu and simd: 1 and 3 against 2) and with device chunks of
7 samples (vulkan) equals the default recording, and a recording in another process equals it too.
A refactoring that moves no number is checked by the same tool against the recording of the build
before it (docs/physics.md, "One text for every backend")."""

import os
import subprocess
import sys

TOOL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools", "tod_fingerprint.py")


def record(path, *args):
    done = subprocess.run([sys.executable, TOOL, "record", str(path), *args], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    print(done.stdout.strip())
    return path


def compare(a, b):
    done = subprocess.run([sys.executable, TOOL, "compare", str(a), str(b)], capture_output=True, text=True)
    print(done.stdout.strip()[-3000:])
    return done.returncode, done.stdout


def test_the_same_bits_whatever_the_threads_and_chunks(tmp_path):
    base = record(tmp_path / "default.npz")
    again = record(tmp_path / "again.npz")
    other = record(tmp_path / "other.npz", "--threads", "1", "--chunk-samples", "7")
    more = record(tmp_path / "more.npz", "--threads", "3")
    for name, path in (("another process", again), ("1 thread, chunks of 7", other), ("3 threads", more)):
        status, out = compare(base, path)
        assert status == 0, f"{name}: {out[-2000:]}"
    # The comparison itself can fail: a recording with one array changed in its last bit differs.
    import numpy as np

    data = dict(np.load(base))
    key = sorted(data)[0]
    flat = data[key].reshape(-1).copy()
    flat.view(np.uint64)[0] ^= 1  # the last bit of the first number
    data[key] = flat.reshape(data[key].shape)
    np.savez(tmp_path / "changed.npz", **data)
    status, out = compare(base, tmp_path / "changed.npz")
    assert status == 1 and f"differs: {key}" in out
