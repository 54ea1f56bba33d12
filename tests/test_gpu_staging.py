#!/usr/bin/env python3
"""Test of scripts/gpu/pack.sh and unpack.sh, which carry the staged binaries and libraries to
the lent GPU machine in one solid archive.

    python3 tests/test_gpu_staging.py

On a staging folder made here with contents drawn afresh (binaries sharing a large block,
as the test binaries share the static library; one without its exec bit; a library; an
A/B binary in base/): pack.sh leaves only staged.tar.xz, smaller than the binaries'
shared block twice over; a second pack.sh with a file added to base/ keeps the first
ones; unpack.sh on a copy restores every file byte for byte, the binaries executable,
and removes the archive; it also unpacks a file compressed on its own (an older
staging) and does nothing on an empty folder; pack.sh refuses an empty folder.
"""
import os
import random
import shutil
import stat
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
PACK = os.path.join(REPO, "scripts", "gpu", "pack.sh")
UNPACK = os.path.join(REPO, "scripts", "gpu", "unpack.sh")
sys.path.insert(0, HERE)
from script_checks import check, finish  # noqa: E402

rng = random.Random()


def run(script, folder):
    return subprocess.run(["bash", script, folder], capture_output=True, text=True)


def write(path, data, executable):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(data)
    os.chmod(path, 0o755 if executable else 0o644)


def tree(folder):
    """Relative path -> bytes of every file under folder."""
    out = {}
    for root, _, files in os.walk(folder):
        for name in files:
            p = os.path.join(root, name)
            with open(p, "rb") as f:
                out[os.path.relpath(p, folder)] = f.read()
    return out


work = tempfile.mkdtemp(prefix="strata-staging-test-")
try:
    stage = os.path.join(work, ".carry")
    shared = rng.randbytes(rng.randint(400_000, 700_000))  # the block every binary holds
    files = {
        "bin/test_a": (shared + rng.randbytes(rng.randint(1, 5000)), True),
        "bin/test_b": (rng.randbytes(rng.randint(1, 5000)) + shared, False),  # no exec bit
        "lib/libx.so.1": (rng.randbytes(rng.randint(1, 20000)), False),
        "base/bench.head": (shared + rng.randbytes(rng.randint(1, 5000)), True),
    }
    for rel, (data, executable) in files.items():
        write(os.path.join(stage, rel), data, executable)
    write(os.path.join(stage, "COMMIT"), b"abc1234\n", False)

    r = run(PACK, stage)
    check(r.returncode == 0, f"pack.sh exit status {r.returncode}: {r.stderr}")
    archive = os.path.join(stage, "staged.tar.xz")
    check(os.path.isfile(archive), "pack.sh wrote no staged.tar.xz")
    check(sorted(os.listdir(stage)) == ["COMMIT", "staged.tar.xz"],
          f"pack.sh left {sorted(os.listdir(stage))} (only COMMIT and the archive expected)")
    if os.path.isfile(archive):
        size = os.path.getsize(archive)
        check(size < 2 * len(shared),
              f"the archive ({size} bytes) does not store the shared block once "
              f"({len(shared)} bytes, three binaries hold it)")

    # a second pack with a file added to base/: the first files stay
    added = rng.randbytes(rng.randint(1, 3000))
    write(os.path.join(stage, "base/bench.other"), added, True)
    files["base/bench.other"] = (added, True)
    r = run(PACK, stage)
    check(r.returncode == 0, f"second pack.sh exit status {r.returncode}: {r.stderr}")

    # unpack on a copy, as the device does
    device = os.path.join(work, "device", ".carry")
    shutil.copytree(stage, device)
    r = run(UNPACK, device)
    check(r.returncode == 0, f"unpack.sh exit status {r.returncode}: {r.stderr}")
    check(not os.path.exists(os.path.join(device, "staged.tar.xz")),
          "unpack.sh left the archive in place")
    got = tree(device)
    for rel, (data, _) in files.items():
        check(got.get(rel) == data, f"{rel} not restored byte for byte")
        if rel.startswith(("bin/", "base/")) and rel in got:
            mode = os.stat(os.path.join(device, rel)).st_mode
            check(mode & stat.S_IXUSR, f"{rel} is not executable after unpacking")
    check(got.get("COMMIT") == b"abc1234\n", "COMMIT changed")

    # a file compressed on its own, as an older staging left it
    single = os.path.join(work, "old", ".carry")
    data = rng.randbytes(rng.randint(1, 4000))
    write(os.path.join(single, "bin/tool"), data, True)
    subprocess.run(["xz", os.path.join(single, "bin/tool")], check=True)
    r = run(UNPACK, single)
    check(r.returncode == 0, f"unpack.sh (single file) exit status {r.returncode}: {r.stderr}")
    check(tree(single) == {"bin/tool": data}, "a single .xz file was not unpacked in place")

    # nothing staged: unpack does nothing, pack refuses
    empty = os.path.join(work, "empty")
    os.makedirs(empty)
    r = run(UNPACK, empty)
    check(r.returncode == 0 and os.listdir(empty) == [],
          f"unpack.sh on an empty folder: status {r.returncode}, left {os.listdir(empty)}")
    r = run(PACK, empty)
    check(r.returncode != 0 and "nothing staged" in r.stderr,
          f"pack.sh on an empty folder: status {r.returncode}, stderr {r.stderr!r}")
finally:
    shutil.rmtree(work, ignore_errors=True)

finish("ok: pack.sh and unpack.sh checks passed")
