"""What every benchmark results file records about its run: date, command, git commit
(and whether the tree had uncommitted changes), host, CPU, hardware threads, GPU."""
from __future__ import annotations

import os
import platform
import shlex
import subprocess
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def command_output(cmd: list[str]) -> str:
    """The stripped standard output of cmd run in the repository ("" when it cannot run)."""
    try:
        return subprocess.run(cmd, capture_output=True, text=True, cwd=REPO).stdout.strip()
    except OSError:
        return ""


def carried_commit() -> str:
    """The commit in .carry/COMMIT (scripts/gpu/prepare.sh), or ""."""
    try:
        with open(os.path.join(REPO, ".carry", "COMMIT")) as f:
            return f.read().strip()
    except OSError:
        return ""


def metadata(argv: list[str]) -> dict:
    """The run's metadata: date (UTC), command (argv quoted), git commit and dirtiness,
    machine (host, CPU model from /proc/cpuinfo, hardware threads, first GPU's name)."""
    cpu = ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    gpu = command_output(["sh", "-c", "nvidia-smi --query-gpu=name --format=csv,noheader "
                          "2>/dev/null | head -1"])
    return {
        "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "command": " ".join(shlex.quote(a) for a in argv),
        # STRATA_CARRIED=1 (scripts/gpu/run_e2e.sh on the lent GPU machine): the binaries
        # are the staged ones, so their commit is the one prepare.sh recorded
        "git_commit": (carried_commit().split()[0] if os.environ.get("STRATA_CARRIED") == "1"
                       and carried_commit() else "")
        or command_output(["git", "rev-parse", "--short", "HEAD"]),
        "git_dirty": ("uncommitted" in carried_commit())
        if os.environ.get("STRATA_CARRIED") == "1"
        else bool(command_output(["git", "status", "--porcelain", "--untracked-files=no"])),
        "machine": {"host": platform.node(), "cpu": cpu,
                    "hardware_threads": os.cpu_count(), "gpu": gpu},
    }
