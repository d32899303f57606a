"""The documentation: the Sphinx site builds offline with warnings as errors, and benchmarks/results holds exactly
the results that the README and the docs cite."""

import json
import pathlib
import re
import subprocess
import sys

from conftest import HANG_S

ROOT = pathlib.Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
COMPANION_SUFFIXES = (".md", ".png", "_episodes.png", "_env_steps.png", "_contacts.png")
CITED = re.compile(r"benchmarks/results/([A-Za-z0-9_.\-]+\.(?:json|png|md))")


def test_docs_build_without_warnings(tmp_path):
    command = [
        sys.executable,
        "-m",
        "sphinx",
        "-E",
        "-W",
        "--keep-going",
        "-q",
        "-b",
        "html",
        str(ROOT / "docs"),
        str(tmp_path / "html"),
    ]
    done = subprocess.run(command, capture_output=True, text=True, timeout=HANG_S)
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "html" / "modules" / "genrl.html").exists()


def _cited() -> set[str]:
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "docs").rglob("*.rst"))]
    return {name for page in pages for name in CITED.findall(page.read_text(encoding="utf-8"))}


def _companions(cited: set[str]) -> set[str]:
    """What a benchmark writes beside a cited JSON: its Markdown table and its plots."""
    stems = [name.removesuffix(".json") for name in cited if name.endswith(".json")]
    return {stem + suffix for stem in stems for suffix in COMPANION_SUFFIXES}


def test_every_cited_result_exists_and_every_result_is_cited():
    cited = _cited()
    assert cited, "no benchmarks/results file is cited"
    missing = sorted(name for name in cited if not (RESULTS / name).is_file())
    assert missing == [], f"cited but not in benchmarks/results: {missing}"
    uncited = sorted(path.name for path in RESULTS.iterdir() if path.name not in cited | _companions(cited))
    assert uncited == [], f"in benchmarks/results but cited by neither the README nor the docs: {uncited}"


def test_docs_page_layout():
    page = (ROOT / "docs" / "modules" / "genrl.rst").read_text(encoding="utf-8")
    for section in ("Notes", "Can I use?", "Example", "Results", "How to replicate the results?", "Parameters"):
        assert f"\n{section}\n" in page, section


def test_results_page_holds_the_fetch_tables_as_written():
    """docs/results.md copies benchmarks/results/fetch.md's tables (written by benchmarks/fetch_results.py): every
    row there must be on the page unchanged, so a hand edit cannot drift from the table."""
    page = (ROOT / "docs" / "results.md").read_text(encoding="utf-8").splitlines()
    rows = [line for line in (RESULTS / "fetch.md").read_text(encoding="utf-8").splitlines() if line.startswith("|")]
    assert rows and [row for row in rows if row not in page] == []


def test_every_result_records_the_package_version_and_the_commit():
    """Each result JSON names the sb3-genrl version and the git commit of the code that made it."""
    unrecorded = []
    for path in sorted(RESULTS.glob("*.json")):
        result = json.loads(path.read_text(encoding="utf-8"))
        if not (
            isinstance(result, dict)
            and result.get("sb3_genrl")
            and re.fullmatch(r"[0-9a-f]{40}(\+dirty)?", str(result.get("git_commit")))
        ):
            unrecorded.append(path.name)
    assert unrecorded == []


# N beside an iteration's or episodes' words; not an option's or keyword's placeholder (--episodes N, goals=N), an
# array's leading dimension ((N, T, M)) or the paper's notation named once ("the paper's N")
N_NEAR_AN_ITERATION = re.compile(r"episode|iteration|n_steps|per update")


def test_docs_call_the_episodes_of_an_iteration_batch_episodes():
    """The README and the docs name the episodes of one EM iteration ``batch_episodes``, never N."""
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "docs").rglob("*.rst"))]
    found = []
    for page in pages:
        text = " ".join(page.read_text(encoding="utf-8").split())
        for match in re.finditer(r"\bN\b", text):
            before, after = text[: match.start()], text[match.end() :]
            placeholder = re.search(r"-[\w-]+ $", before) or before.endswith("=")
            shape = before.endswith("(") and after.startswith(",")
            if placeholder or shape or before.endswith("the paper's "):
                continue
            near = text[max(0, match.start() - 80) : match.end() + 80]
            if N_NEAR_AN_ITERATION.search(near):
                found.append(f"{page.relative_to(ROOT)}: ...{near}...")
    assert found == [], "\n".join(found)
