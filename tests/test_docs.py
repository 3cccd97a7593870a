"""The documentation keeps its promises.

* Every author–year citation (and every "Name et al.", "Name (3.45)", "Name Alg. 5.2" citation) in the code and
  the README names an entry of ``docs/references.md`` that holds every cited name and the year.
* Every ``spec NNN`` / ``thesis NNN`` the code cites is named in ``docs/references.md``.
* The README's prose links its citations into ``docs/references.md`` (no bare "Merino", "Ross et al.").
* Every relative link in the docs and the README points at a file (and anchor) that exists.
* Every gallery script runs, exits 0 and prints its expected line; a script without an expectation fails.
"""

from __future__ import annotations

import os
import re
import resource
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
REFERENCES = DOCS / "references.md"
GALLERY = DOCS / "gallery"
CODE_PACKAGES = ("agent", "fusion", "mesh_sim", "perception", "tasking", "deploy")

_NAME = r"(?:Van |D')?[A-Z][a-zà-öø-ÿ]+(?:-[A-Z][a-zà-öø-ÿ]+)?"
_AUTHORS = rf"{_NAME}(?:(?:,\s+|\s+and\s+|\s+&\s+){_NAME})*"
_YEAR = r"(?:19|20)\d\d"
CITATION_PATTERNS = (
    # Niehsen, 2002 / Blom & Bar-Shalom 1988 / Musso et al. (2001) / Niehsen's (2002) / Olfati-Saber, CDC 2009
    re.compile(rf"\b(?P<a>{_AUTHORS})(?:\s+et al\.)?(?:'s)?,?\s+(?:[A-Z][A-Za-z]*,?\s+)?\(?(?P<y>{_YEAR})\b"),
    # Dempster, "Covariance selection", Biometrics 1972
    re.compile(rf"\b(?P<a>{_AUTHORS}),?\s+\"[^\"]+\",?\s+[^()\"]*?(?P<y>{_YEAR})\b"),
    # Tarjan's bridge-finding algorithm (1974)
    re.compile(rf"\b(?P<a>{_NAME})'s\s+[\w\- ]{{0,40}}\((?P<y>{_YEAR})\)"),
    # Zhao et al.
    re.compile(rf"\b(?P<a>{_NAME})\s+et al\."),
    # Merino (3.45) / Merino Alg. 5.2 / Groves §2.4.2 / Bethke (spec 000 §2.8)
    re.compile(rf"\b(?P<a>{_NAME})\s+(?:\(\d+\.\d+\)|Alg\.\s?\d|Eqs?\.\s?\d|§\s?\d|\(spec\s)"),
)
#: Capitalised words the last pattern catches that are not authors ("Solve Eqs. 14-17", "Thesis §3.3").
NOT_AUTHORS = frozenset({"Gaussian", "Guidance", "Solve", "Thesis"})
SOURCE_NUMBER = re.compile(r"\b(?:spec|thesis)\s+(\d{3}[ab]?)\b", re.IGNORECASE)
REFERENCE_LINK = re.compile(r"\[[^\]]*\]\(docs/references\.md#([\w-]+)\)")
RELATIVE_LINK = re.compile(r"\]\((?!https?:|mailto:)([^)#\s]*)(?:#([\w-]+))?\)")
CODE_BLOCK = re.compile(r"```.*?```", re.S)
INLINE_CODE = re.compile(r"`[^`\n]+`")


def citations(text: str) -> set[tuple[tuple[str, ...], str | None]]:
    """The citations in ``text``: (the cited surnames, the year or ``None``)."""
    found = set()
    for pattern in CITATION_PATTERNS:
        for match in pattern.finditer(text):
            names = tuple(n for n in re.split(r",\s+|\s+and\s+|\s+&\s+", match.group("a")) if n not in NOT_AUTHORS)
            if names:
                found.add((names, match.groupdict().get("y")))
    return found


def reference_entries() -> dict[str, str]:
    """``docs/references.md``: anchor -> the entry's text (one list item)."""
    text = REFERENCES.read_text(encoding="utf-8")
    items = re.split(r"\n(?=- <a id=\")", text)
    return {m.group(1): item for item in items if (m := re.match(r"- <a id=\"([\w-]+)\"></a>", item))}


def _resolves(citation: tuple[tuple[str, ...], str | None], entries: dict[str, str]) -> bool:
    names, year = citation
    return any(all(re.search(rf"(?<!\w){re.escape(n)}(?!\w)", e) for n in names) and (year is None or year in e)
               for e in entries.values())


def _code_files() -> list[Path]:
    return sorted(p for package in CODE_PACKAGES for p in (ROOT / package).rglob("*.py"))


def _readme_prose() -> str:
    """The README without code: what a reader takes for prose."""
    return INLINE_CODE.sub("", CODE_BLOCK.sub("", (ROOT / "README.md").read_text(encoding="utf-8")))


def test_the_extractor_finds_each_citation_form_and_nothing_else():
    text = ('Fused (Blom & Bar-Shalom, 1988) after Musso et al. (2001); weights of Niehsen\'s (2002) rule;\n'
            'Dempster, "Covariance selection",\n    Biometrics 1972; Tarjan\'s bridge-finding algorithm (1974);\n'
            'spaced (Zhao et al.); update Merino (3.52), Merino Alg. 5.2, Groves §2.4.2. Solve Eqs. 14-17.\n'
            'Python 3.11 and a Gaussian in 2 s; the Kalman filter.')
    assert citations(text) == {
        (("Blom", "Bar-Shalom"), "1988"), (("Musso",), "2001"), (("Musso",), None), (("Niehsen",), "2002"),
        (("Dempster",), "1972"), (("Biometrics",), "1972"),  # a venue and year: the entry must hold them too
        (("Tarjan",), "1974"), (("Zhao",), None), (("Merino",), None), (("Groves",), None),
    }


def test_the_resolver_rejects_an_unknown_author_and_a_wrong_year():
    entries = reference_entries()
    assert _resolves((("Niehsen",), "2002"), entries)
    assert not _resolves((("Niehsen",), "2003"), entries)
    assert not _resolves((("Nobody",), None), entries)


@pytest.mark.parametrize("path", _code_files() + [ROOT / "README.md"], ids=lambda p: str(p.relative_to(ROOT)))
def test_every_citation_names_an_entry_of_the_references(path):
    entries = reference_entries()
    missing = sorted(c for c in citations(path.read_text(encoding="utf-8")) if not _resolves(c, entries))
    assert not missing, f"cited in {path.relative_to(ROOT)} but not in docs/references.md: {missing}"


def test_every_numbered_source_is_named_in_the_references():
    cited = {m.group(1).lower() for p in _code_files() for m in SOURCE_NUMBER.finditer(p.read_text(encoding="utf-8"))}
    named = {m.group(1).lower() for m in SOURCE_NUMBER.finditer(REFERENCES.read_text(encoding="utf-8"))}
    assert cited, "the code cites no numbered source: the pattern is wrong"
    assert cited <= named, f"numbered sources missing from docs/references.md: {sorted(cited - named)}"


def test_the_readme_prose_links_every_citation_into_the_references():
    prose = _readme_prose()
    anchors = set(reference_entries())
    linked = [m.group(1) for m in REFERENCE_LINK.finditer(prose)]
    assert linked and set(linked) <= anchors, f"links to no entry: {sorted(set(linked) - anchors)}"
    bare = REFERENCE_LINK.sub("", prose)
    assert not citations(bare), f"README citations that are not links: {sorted(citations(bare))}"
    assert not SOURCE_NUMBER.findall(bare), f"README 'spec NNN' that are not links: {SOURCE_NUMBER.findall(bare)}"
    assert "DESIGN.md" not in bare, "the README points at DESIGN.md, which is not in the repository"


def _anchors(markdown: Path) -> set[str]:
    text = markdown.read_text(encoding="utf-8")
    explicit = set(re.findall(r"<a id=\"([\w-]+)\"", text))
    headings = {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-")
                for h in re.findall(r"^#+ (.+)$", CODE_BLOCK.sub("", text), re.M)}
    return explicit | headings


@pytest.mark.parametrize("page", [ROOT / "README.md", *sorted(DOCS.glob("*.md"))], ids=lambda p: p.name)
def test_every_relative_link_resolves(page):
    broken = []
    for target, anchor in RELATIVE_LINK.findall(CODE_BLOCK.sub("", page.read_text(encoding="utf-8"))):
        path = (page.parent / target).resolve() if target else page
        if not path.exists() or (anchor and path.suffix == ".md" and anchor not in _anchors(path)):
            broken.append(f"{target}#{anchor}" if anchor else target)
    assert not broken, f"{page.name}: broken links {broken}"


DEFINED_KEY = re.compile(r"\*\*\[(\w+)\]\*\*")
USED_KEY = re.compile(r"\[([A-Z][A-Za-z]+\d{0,4}[ab]?)\](?![(\]])")


@pytest.mark.parametrize("page", [*sorted(DOCS.glob("*.md")), *sorted(GALLERY.glob("*.py"))], ids=lambda p: p.name)
def test_every_reference_key_is_defined(page):
    defined = set(DEFINED_KEY.findall(REFERENCES.read_text(encoding="utf-8")))
    used = set(USED_KEY.findall(page.read_text(encoding="utf-8")))
    assert not used - defined, f"{page.name} uses keys that docs/references.md does not define: {used - defined}"


#: What each gallery script must print (a regular expression, multi-line); a script without one fails.
GALLERY_EXPECTS = {
    "bearings_two_agents_vs_centralized.py": r"^decentralized equals centralized: True$",
    "channel_filter_on_a_lossy_tree.py": r"^loss 30%: .*\n  every agent equals the centralized filter: True$",
    "covariance_intersection_on_a_ring.py":
        r"^ +naive: ANEES +[\d.]+ +overconfident$(?s:.*)^ +ci: ANEES +[\d.]+ +(consistent|conservative)$",
    "certainty_grid_two_agents.py": r"^after two exchanges both agents equal the centralized grid: True$",
    # fused: error and both spreads under 10 m (each UAV alone: a wedge tens of metres long)
    "particle_belief_from_bearings.py": r"^ +fused: error +\d\.\d\d m, spread +\d\.\d\d m x +\d\.\d\d m$",
    "lockstep_run_and_metrics.py": r"^status: completed$",
}
GALLERY_CPU_S = 20.0  # each script's own CPU time (user + system); the wall time depends on the machine's load


def test_every_gallery_script_has_an_expectation_and_an_index_line():
    scripts = {p.name for p in GALLERY.glob("*.py")}
    assert scripts == set(GALLERY_EXPECTS), f"scripts without an expectation: {scripts - set(GALLERY_EXPECTS)}"
    index = (DOCS / "README.md").read_text(encoding="utf-8")
    assert all(f"(gallery/{name})" in index for name in scripts), "docs/README.md must link every gallery script"


#: Scripts that run a whole team (a lockstep run): slow, like the golden lockstep runs.
SLOW_SCRIPTS = frozenset({"lockstep_run_and_metrics.py"})


@pytest.mark.parametrize("name", [pytest.param(n, marks=[pytest.mark.slow] if n in SLOW_SCRIPTS else [])
                                  for n in sorted(GALLERY_EXPECTS)])
def test_gallery_script_runs_and_prints_its_result(name):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([sys.executable, str(GALLERY / name)], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                          capture_output=True, text=True, timeout=300)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert done.returncode == 0, f"{name} exited {done.returncode}:\n{done.stderr[-3000:]}"
    assert re.search(GALLERY_EXPECTS[name], done.stdout, re.M), f"{name} printed:\n{done.stdout}"
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    assert cpu < GALLERY_CPU_S, f"{name} took {cpu:.1f} s of CPU"
