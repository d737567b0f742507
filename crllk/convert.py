"""``python -m crllk.convert path=<file or run directory> trust=true``: older checkpoints in the
format that loads without running code.

Every command reads checkpoints (``<run>/checkpoints/*.pt``) and kept policies
(``<run>/policy.pt``) with ``torch.load(weights_only=True)``: tensors and plain containers
only, so reading a file cannot run code. A checkpoint written before format 4 also holds numpy
arrays and a TensorDict, which only a full unpickling reads, and a full unpickling runs
whatever code the file names; so the commands refuse it, as they refuse a file crafted to run
code. This command converts one you trust, e.g. a run you trained with an earlier version:

    python -m crllk.convert path=runs/small_loop/crllk-discrete-state-seed0 trust=true
    python -m crllk.convert path=old_run/checkpoints/last.pt trust=true

``trust=true`` is the opt-in: with it each file that needs converting is fully unpickled, and
any code in it runs. Pass it only for files you wrote yourself or got from someone you trust.
Without it nothing is unpickled: the command names the first file that needs converting and
exits with status 2. A run directory converts its ``policy.pt`` and every ``checkpoints/*.pt``;
each file is rewritten in place, atomically; a file that already loads without running code is
left as it is.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from crllk.cli import run
from crllk.errors import ConfigError
from crllk.rl.plain import as_plain, first_non_plain
from crllk.settings import MISSING, parse_dotlist, setting
from crllk.training.checkpoints import (
    CONVERTED_FORMATS,
    POLICY_FILE,
    UnsafeFileError,
    check_format,
    read_state,
    write_state,
)
from crllk.training.runs import CHECKPOINT_FILE

SOURCE = "convert"


@dataclass
class ConvertConfig:
    """Command-line settings (``key=value``)."""

    path: str = setting(MISSING)
    """A checkpoint or policy file, or a run directory (its ``policy.pt`` and
    ``checkpoints/*.pt``)."""
    trust: bool = False
    """Fully unpickle the files that need converting, running any code in them: only for
    files you trust."""

    def problems(self) -> Iterator[tuple[str, str]]:
        path = Path(self.path)
        if path.is_dir() and (folder := path / CHECKPOINT_FILE.parent).is_symlink():
            yield "path", f"{folder} is a symbolic link, which is not followed (remove it)"
        elif not path.exists():
            yield "path", f"no such file or run directory: {path}"
        elif path.is_dir() and not run_files(path):
            yield "path", (f"{path} holds neither {POLICY_FILE} nor "
                           f"{CHECKPOINT_FILE.parent}/*.pt")


def run_files(run_dir: Path) -> list[Path]:
    """A run directory's kept policy and checkpoints, those that exist."""
    policy = run_dir / POLICY_FILE
    return ([policy] if policy.is_file() else []) + sorted(
        (run_dir / CHECKPOINT_FILE.parent).glob("*.pt"))


def convert_file(path: Path, *, trust: bool) -> str:
    """Rewrites ``path`` in tensors and plain containers, fully unpickling it only when it
    needs converting and ``trust`` is given; returns what was done, on one line.

    Raises:
        ConfigError: if the file needs converting and ``trust`` is off, or if it is not a
            readable checkpoint, or holds what cannot be converted.
    """
    try:
        check_format(path, read_state(path))
        return f"{path}: loads without running code, left as it is"
    except UnsafeFileError:
        if not trust:
            raise ConfigError(SOURCE, "trust", (
                f"{path} holds pickled Python objects, which may execute code when loaded: "
                "pass trust=true to load and convert it, only if you trust the file")) from None
    state = read_state(path, trust=True)
    check_format(path, state)
    old = state["format"]  # type: ignore[index]
    converted = {**as_plain(state), "format": CONVERTED_FORMATS.get(old, old)}
    problem = first_non_plain(converted)
    if problem:
        raise ConfigError(path, "<file>", f"cannot be converted: it holds {problem}, not "
                          "tensors and plain containers")
    write_state(path, converted)
    check_format(path, read_state(path))
    return f"{path}: converted from format {old} to {converted['format']}"


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if {"-h", "--help"} & set(argv):
        print(__doc__)
        return 0
    config = parse_dotlist(ConvertConfig, argv, SOURCE)
    path = Path(config.path)
    for file in run_files(path) if path.is_dir() else [path]:
        print(convert_file(file, trust=config.trust), flush=True)
    return 0


if __name__ == "__main__":
    run(main)
