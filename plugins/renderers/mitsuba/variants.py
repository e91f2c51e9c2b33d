"""Which Mitsuba 3 variant renders: ``cuda_ad_rgb`` on a GPU, ``llvm_ad_rgb`` on the CPU, else ``scalar_rgb``.

Mitsuba's JIT variants compile their kernels with LLVM (CPU) or CUDA at run time, and a broken
LLVM does not raise an error: the system LLVM 15 of Debian 12 dies with an instruction-selection
error on AVX-512 machines and takes the process with it. So every variant is first tried in a
**subprocess** that renders a tiny scene with the ``path`` integrator (the same kind of kernel a
frame compiles); only a variant whose probe exits cleanly is used in this process.

The LLVM library is the one ``DRJIT_LIBLLVM_PATH`` names, else Dr.Jit's own search. Where that one
fails (or the variable is unset), the other ``libLLVM-*.so`` files of the system's library folders
are tried, newest first; a working one is put in ``DRJIT_LIBLLVM_PATH`` for this process and the
processes it starts with a warning saying so (Dr.Jit reads the variable when it is imported, so
this works where the process has not imported Mitsuba yet). With none, ``auto``
falls back to ``scalar_rgb`` with a one-line warning naming what to install and which variable
to set (:data:`LLVM_HINT`); a variant asked for by name is an error instead.

A probe's verdict is kept in the environment (:data:`PROBED`), so the worker processes of a run
do not probe again.
"""

from __future__ import annotations

import contextlib
import ctypes.util
import glob
import importlib.util
import os
import re
import subprocess
import sys
import warnings

#: the renderer's ``variant`` setting -> Mitsuba variant
VARIANTS = {"cuda": "cuda_ad_rgb", "llvm": "llvm_ad_rgb", "scalar": "scalar_rgb"}
#: the variable naming the LLVM library Dr.Jit loads
LLVM_VARIABLE = "DRJIT_LIBLLVM_PATH"
#: what a user does when no LLVM works
LLVM_HINT = ("install Debian's libllvm19 (apt-get install libllvm19) and set "
             "DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so")
#: environment variable holding the verdicts of this process tree's probes ("variant=ok|fail;...")
PROBED = "DENOISE_MITSUBA_PROBED"
#: seconds a probe may take (an import, a scene and one kernel compile)
PROBE_TIMEOUT = 180
#: folders searched for other LLVM libraries
LIBRARY_DIRS = ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64", "/usr/lib",
                "/usr/local/lib")

_PROBE = """
import sys
import mitsuba as mi
mi.set_variant(sys.argv[1])
scene = mi.load_dict({"type": "scene", "light": {"type": "constant"},
                      "ball": {"type": "sphere", "bsdf": {"type": "diffuse"}},
                      "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, -1]).scale(4)},
                      "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().look_at(
                          origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                          "film": {"type": "hdrfilm", "width": 8, "height": 8}}})
image = mi.render(scene, integrator=mi.load_dict({"type": "path", "max_depth": 4}), spp=4)
value = float(sum(float(v) for v in mi.TensorXf(image).array) / (8 * 8 * 3))
sys.exit(0 if 0.0 < value < 10.0 else 3)
"""


class VariantError(ValueError):
    """The variant asked for cannot run here."""


def _verdicts() -> dict[str, str]:
    text = os.environ.get(PROBED, "")
    return dict(item.split("=", 1) for item in text.split(";") if "=" in item)


def _remember(key: str, verdict: str) -> None:
    verdicts = _verdicts()
    verdicts[key] = verdict
    os.environ[PROBED] = ";".join(f"{k}={v}" for k, v in sorted(verdicts.items()))


def probe(variant: str, libllvm: str | None = None) -> bool:
    """True if ``variant`` renders a tiny scene in a subprocess (with ``libllvm`` as Dr.Jit's LLVM).

    The verdict is cached in the environment per (variant, library).
    """
    key = f"{variant}@{libllvm or os.environ.get(LLVM_VARIABLE, '')}"
    cached = _verdicts().get(key)
    if cached is not None:
        return cached == "ok"
    env = dict(os.environ)
    if libllvm is not None:
        env[LLVM_VARIABLE] = libllvm
    try:
        done = subprocess.run([sys.executable, "-c", _PROBE, variant], env=env, capture_output=True,
                              timeout=PROBE_TIMEOUT)
        ok = done.returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        ok = False
    _remember(key, "ok" if ok else "fail")
    return ok


def llvm_candidates() -> list[str]:
    """Other ``libLLVM-<major>.so`` files of the system, newest first."""
    found = {}
    for folder in LIBRARY_DIRS:
        for path in glob.glob(os.path.join(folder, "libLLVM-*.so")) + glob.glob(os.path.join(folder, "libLLVM.so.*")):
            match = re.search(r"libLLVM(?:-|\.so\.)(\d+)", os.path.basename(path))
            if match:
                found.setdefault(int(match.group(1)), os.path.realpath(path))
    return [found[k] for k in sorted(found, reverse=True)]


def _cuda_present() -> bool:
    return ctypes.util.find_library("cuda") is not None or os.path.exists("/dev/nvidia0")


def installed() -> set[str]:
    """The variants the installed Mitsuba has, found without importing it (which would load LLVM)."""
    spec = importlib.util.find_spec("mitsuba")
    if spec is None or not spec.origin:
        return set()
    folder = os.path.dirname(spec.origin)
    names = {os.path.basename(path).split(".")[0] for path in glob.glob(os.path.join(folder, "*_*.*"))}
    return names & set(VARIANTS.values())


def _llvm_works() -> bool:
    """Probe the LLVM Dr.Jit would load, then the others; set :data:`LLVM_VARIABLE` to one that works.

    Dr.Jit reads :data:`LLVM_VARIABLE` when it is imported, so another library can only be chosen
    while this process has not imported it yet.
    """
    if probe(VARIANTS["llvm"]):
        return True
    if "drjit" in sys.modules:
        return False
    current = os.environ.get(LLVM_VARIABLE)
    for path in llvm_candidates():
        if path == (os.path.realpath(current) if current else None):
            continue
        if probe(VARIANTS["llvm"], path):
            os.environ[LLVM_VARIABLE] = path
            warnings.warn(f"renderer 'mitsuba': {LLVM_VARIABLE} set to {path} for this run (the LLVM Dr.Jit "
                          f"found {'there' if current else 'by itself'} failed its probe)", stacklevel=4)
            return True
    return False


def choose(requested: str = "auto") -> str:
    """The Mitsuba variant for the ``variant`` setting ``requested``.

    Parameters
    ----------
    requested : {"auto", "cuda", "llvm", "scalar"} or a full variant name
        ``auto``: ``cuda_ad_rgb`` where a GPU works, else ``llvm_ad_rgb`` where an LLVM works,
        else ``scalar_rgb`` with a warning. A named variant must work.

    Raises
    ------
    VariantError
        A named variant that is not installed or fails its probe (one line, with the fix).
    """
    present = installed()
    name = VARIANTS.get(requested, requested)
    if requested == "auto":
        if VARIANTS["cuda"] in present and _cuda_present() and probe(VARIANTS["cuda"]):
            return VARIANTS["cuda"]
        if VARIANTS["llvm"] in present and _llvm_works():
            return VARIANTS["llvm"]
        warnings.warn(f"renderer 'mitsuba': no working LLVM for llvm_ad_rgb, rendering with scalar_rgb "
                      f"(much slower); to fix: {LLVM_HINT}", stacklevel=3)
        return VARIANTS["scalar"]
    if name not in VARIANTS.values():
        raise VariantError(f"renderer 'mitsuba': variant must be one of auto, {', '.join(VARIANTS)} "
                           f"(or {', '.join(VARIANTS.values())}), got {requested!r}")
    if name not in present:
        raise VariantError(f"renderer 'mitsuba': the installed Mitsuba has no variant {name}")
    if name == VARIANTS["llvm"] and not _llvm_works():
        raise VariantError(f"renderer 'mitsuba': llvm_ad_rgb does not work here: {LLVM_HINT}")
    if name == VARIANTS["cuda"] and not (_cuda_present() and probe(name)):
        raise VariantError("renderer 'mitsuba': cuda_ad_rgb does not work here (no usable CUDA GPU)")
    return name


@contextlib.contextmanager
def active(mi, name: str):
    """Make ``name`` Mitsuba's variant for the body, then restore the one set before (if any)."""
    previous = mi.variant()
    if previous != name:
        mi.set_variant(name)
    try:
        yield mi
    finally:
        if previous is not None and previous != name:
            mi.set_variant(previous)
