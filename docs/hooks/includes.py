"""MkDocs hook: the site shows the committed results as the experiments wrote them.

A page includes a file of the repository with a line of its own::

    <!-- include results/pixels/table1.md -->           the file (missing: the build fails)
    <!-- include-if-present results/pixels/aids.md -->  the file, or a note that it is not yet
    <!-- include README.md#in-short -->                 the part of a file between
                                                        ``<!-- section in-short -->`` and
                                                        ``<!-- /section in-short -->``

The API reference has a page per package of ``crllk`` (``reference/<package>.md``, listed in
:data:`REFERENCE`), written here from the package's modules as they are, so a module added,
moved or removed is in the reference at the next build without anyone listing it.

An included file's headings move one level down when it starts with a title (``# ...``), so
that it sits below the page's own; links into ``docs/`` (written for the repository's view
of the file) are made relative to the including page. The pictures under ``results/`` are
published at the same paths, so a page of ``docs/results/`` shows ``results/pixels/sweep.png``
as ``pixels/sweep.png``. In the API reference, the Sphinx roles of docstrings
(``:class:`Name```) are dropped before their code.
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

REPO = Path(__file__).resolve().parents[2]
PICTURES = ("results/*/*.png",)
_DIRECTIVE = re.compile(r"^<!-- (include|include-if-present) (\S+?)(?:#(\S+))? -->$", re.MULTILINE)
_HEADING = re.compile(r"^(#{1,5}) ", re.MULTILINE)
_DOCS_LINK = re.compile(r"\]\(docs/([^)]*)\)")
_SPHINX_ROLE = re.compile(r":(?:class|func|meth|mod|attr|data|exc|obj):(?=<code)")


REFERENCE = {
    "maps": "Map format, objects, lane geometry and the lane pose.",
    "sim": "MuJoCo only: the scene builder, the floor texture, the motor model and the Physics.",
    "tasks": "The dm-control task, its settings, constraints as data, action mappings, the "
             "scripted follower and the teacher.",
    "envs": "The batched TorchRL environment, episode statistics, worker processes and remote "
            "collectors.",
    "rl": "Lagrange multipliers, the λ-combination of advantages, the PPO loss with its critics, "
          "networks and rollouts.",
    "algos": "The learners, one module each, behind one interface (see the tutorial "
             "[Add a constrained algorithm](../tutorials/add-an-algorithm.md)).",
    "training": "The trainer: composing its settings, building a run, one iteration, logs, "
                "checkpoints, reading run directories.",
    "evaluation": "Evaluating runs and the scripted drivers; the intervals and the robustness "
                  "conditions.",
    "recording": "Recordings with rerun, their layout, the live view and the viewer process.",
    "deployment": "The deterministic policy, its ONNX export, camera frames as in training, the "
                  "pilot, its parity check and the ROS 2 node.",
    "experiments": "The experiments that train and evaluate the tables and figures of "
                   "[Results](../results/index.md), and the readers of finished runs.",
    "peers": "Serving crllk's tasks to another library's Python environment.",
    "analysis": "Figures, map pictures, a picture of a recording, the cost critics' fit and how "
                "episodes end.",
    "bench": "The throughput benchmarks (`python -m crllk.bench` and its parts).",
}
"""The packages of the API reference, each with what it holds."""


def reference_page(package: str, repo: Path = REPO) -> str:
    """The API reference page of ``crllk.<package>``: the package, then each of its modules."""
    modules = sorted(p.stem for p in (repo / "crllk" / package).glob("*.py")
                     if not p.name.startswith("_"))
    blocks = [f"# crllk.{package}", REFERENCE[package], f"::: crllk.{package}",
              *(f"::: crllk.{package}.{module}" for module in modules)]
    return "\n\n".join(blocks) + "\n"


def section(text: str, name: str, path: str) -> str:
    """The lines between ``<!-- section NAME -->`` and ``<!-- /section NAME -->``."""
    start, end = f"<!-- section {name} -->", f"<!-- /section {name} -->"
    if start not in text or end not in text:
        raise PluginError(f"{path}: no section {name!r} (mark it with {start} ... {end})")
    return text.split(start, 1)[1].split(end, 1)[0].strip("\n")


def expand(markdown: str, page: str, repo: Path = REPO) -> str:
    """``markdown`` of the page at ``page`` (its path under ``docs/``) with its includes done."""

    def include(match: re.Match) -> str:
        kind, path, name = match.groups()
        source = repo / path
        if not source.is_file():
            if kind == "include-if-present":
                return f"*`{path}` is not written yet: its experiment has not finished.*"
            raise PluginError(f"{page}: includes {path}, which does not exist")
        text = source.read_text()
        if name:
            text = section(text, name, path)
        if text.lstrip().startswith("# "):
            text = _HEADING.sub(lambda m: "#" + m.group(1) + " ", text)
        prefix = posixpath.relpath(".", posixpath.dirname(page) or ".")
        return _DOCS_LINK.sub(lambda m: f"]({posixpath.join(prefix, m.group(1))})", text)

    return _DIRECTIVE.sub(include, markdown)


def on_files(files, config):
    """Publish the committed result pictures beside the pages, and write the API reference's
    package pages."""
    for package in REFERENCE:
        files.append(File.generated(config, f"reference/{package}.md",
                                    content=reference_page(package)))
    for pattern in PICTURES:
        for picture in sorted(REPO.glob(pattern)):
            uri = picture.relative_to(REPO).as_posix()
            files.append(File(uri, src_dir=str(REPO), dest_dir=config["site_dir"],
                              use_directory_urls=config["use_directory_urls"]))
    return files


def on_page_markdown(markdown, page, config, files):
    return expand(markdown, page.file.src_uri)


def on_page_content(html, page, config, files):
    """The API reference shows a docstring's ``:class:`Name``` as the code ``Name``."""
    return _SPHINX_ROLE.sub("", html)
