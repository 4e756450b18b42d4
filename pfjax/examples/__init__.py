"""Example studies shipped with pfjax: the Monte Carlo study configs of the repository's
``studies/`` folder, packaged so an installed pfjax can run them (``pfjax study --example NAME``;
``pfjax examples`` lists them). Each file is a byte-identical copy of its ``studies/`` source.

    import pfjax
    from pfjax import examples

    examples.names()                      # ['default', 'heldout', 'random_paths', 'slip_frequency', 'rare_events']
    result = pfjax.run_study(examples.path("default"), "results/default", n_runs=1000)
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from pfjax.errors import InputError

__all__ = ["FILES", "describe", "description", "names", "path", "study_file"]

#: Example name -> its file in this package (the same name under ``studies/`` in the repository).
FILES = {
    "default": "robustness_default.toml",  # the default Monte Carlo robustness study
    "heldout": "tuning_heldout.toml",  # the tuning study's held-out set
    "random_paths": "random_paths.toml",
    "slip_frequency": "slip_frequency.toml",
    "rare_events": "rare_events.toml",  # rare failure probabilities ([rare_event])
}


def names() -> list[str]:
    """The example names, in the order ``pfjax examples`` lists them."""
    return list(FILES)


def path(name: str) -> Path:
    """The packaged TOML of example ``name``; an unknown name raises :class:`~pfjax.errors.InputError`
    naming ``example`` and listing the names."""
    if name not in FILES:
        raise InputError(f"example: unknown example {name!r}; expected one of {', '.join(FILES)}", "example")
    return Path(str(resources.files(__name__).joinpath(FILES[name])))


def study_file(value: str | Path) -> Path:
    """A study TOML named in a config: the packaged example if ``value`` is an example's name
    (``"heldout"``, the same meaning wherever the command runs), else the path ``value`` (relative
    to the working directory)."""
    if isinstance(value, str) and value in FILES:
        return path(value)
    return Path(value)


def description(name: str) -> str:
    """One line about example ``name``: the first sentence of the comment the file starts with
    (its first comment lines, joined), or its ``name`` key when the file starts with no comment."""
    text = path(name).read_text(encoding="utf-8")
    comment: list[str] = []
    for line in text.splitlines():
        line = line.strip()
        if not line.startswith("#"):
            if line or comment:
                break
            continue
        comment.append(line.lstrip("#").strip())
    if comment:
        first = " ".join(comment)
        head, sep, _ = first.partition(". ")
        return head + "." if sep else first
    import tomllib

    return str(tomllib.loads(text).get("name", name))


def describe() -> dict[str, str]:
    """``{name: one-line description}`` of every example."""
    return {n: description(n) for n in FILES}
