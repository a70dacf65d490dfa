"""Compiled kernels of the tracker (numba): interval operations, the tapes
(straight-line code generated per robot, or the interpreter), interval linear
algebra, contractors and the step itself.

Nothing here names a robot: a robot's tapes reach the kernels as arrays and
the address of their code (:func:`verifier.compiled.straight.pack`; the
generated code is cached apart, see docs/architecture.md).  Kernels are
compiled once per machine and cached next to this package (``__pycache__``);
the first call after an install pays the compilation (see benchmarks/README.md).
"""

import hashlib
from pathlib import Path


def sources_digest() -> str:
    """A digest of every source the compiled kernels are built from (this
    package, and the reference modules it follows operation for operation)."""
    here = Path(__file__).resolve().parent
    sources = sorted(here.rglob("*.py")) + [here.parent / n for n in ("interval.py", "tape.py", "constants.py")]
    return hashlib.sha256(b"".join(p.read_bytes() for p in sources)).hexdigest()


def _drop_stale_cache() -> None:
    """Delete cached kernels compiled from other sources than these.

    numba re-validates a cached function against its own file only: a kernel
    in ``step.py`` cached before an edit of ``interval.py`` would keep the old
    arithmetic.  The stamp covers every source the kernels are built from.
    A read-only install cannot be edited, so failing to write is harmless.
    """
    here = Path(__file__).resolve().parent
    digest = sources_digest()[:20]
    cache = here / "__pycache__"
    stamp = cache / "kernels.stamp"
    caches = [cache] + [d / "__pycache__" for d in here.iterdir() if d.is_dir() and d.name != "__pycache__"]
    try:
        if stamp.read_text() == digest:
            return
    except OSError:
        pass
    try:
        cache.mkdir(exist_ok=True)
        for d in caches:  # the subpackages' kernels (lanes/) are cached beside their sources
            for f in list(d.glob("*.nbi")) + list(d.glob("*.nbc")):
                f.unlink(missing_ok=True)
        stamp.write_text(digest)
    except OSError:
        pass


_drop_stale_cache()

