"""What a model file records about how it was made: the tool versions, the CPU, the seed and the
command, under the header keys `versions`, `seed` and `command` (shared by `train_landmarks.py`
and `train_proposals.py`; the Rust readers ignore these keys).

The same crops, seed and versions on the same CPU give the same weights; another torch version
or CPU may give a network of the same accuracy but not the same bytes, so the file says which it
was (`scripts/regenerate-models` compares them).
"""

from __future__ import annotations

import os
import platform
import shlex
import sys
from typing import Any


def cpu_model() -> str:
    """The CPU's model name (Linux), else what `platform` knows of it."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def tool_versions() -> dict[str, str]:
    """The versions of Python, numpy and torch this process runs, and the CPU."""
    import numpy
    import torch

    return {
        "python": platform.python_version(),
        "numpy": str(numpy.__version__),
        "torch": str(torch.__version__),
        "cpu": cpu_model(),
    }


def command() -> str:
    """This process's command line, the script's path relative to the working directory."""
    script = os.path.relpath(sys.argv[0]) if sys.argv[0] else "python3"
    return shlex.join(["python3", script, *sys.argv[1:]])


def provenance(seed: int) -> dict[str, Any]:
    """The header entries that record how a model file was made."""
    return {"versions": tool_versions(), "seed": seed, "command": command()}
