"""The README's Python snippets run as written, in order, on the installed package."""
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _snippets():
    with open(os.path.join(ROOT, "README.md")) as f:
        return re.findall(r"```python\n(.*?)```", f.read(), flags=re.S)


def test_readme_python_snippets_each_run_alone(tmp_path):
    """Each snippet in a fresh process and folder of its own (a reader copies one, not all)."""
    blocks = _snippets()
    assert len(blocks) >= 5
    for k, block in enumerate(blocks):
        folder = tmp_path / f"snippet{k}"
        folder.mkdir()
        (folder / "snippet.py").write_text(block)
        r = subprocess.run([sys.executable, "snippet.py"], cwd=folder, capture_output=True,
                           text=True, timeout=900)
        assert r.returncode == 0, (k, block[:200], r.stderr[-3000:])
        if k == 0:
            assert "converged=True" in r.stdout
            assert (folder / "beam.vtu").exists()


def _product_files():
    """README.md and the text files under docs, the packages and configs (A/B configs too)."""
    yield os.path.join(ROOT, "README.md")
    for top in ("docs", "anisofem", "anisognn", "export", "configs", "experiments"):
        for folder, _, files in os.walk(os.path.join(ROOT, top)):
            yield from (os.path.join(folder, f) for f in files
                        if f.endswith((".md", ".toml", ".py")))


def test_readme_and_docs_speak_of_the_product():
    """No planning words (issue numbers, bars, floors, met or not) in what users read."""
    pattern = re.compile(r"issue [0-9]|issue's|\bbars?\b|NOT met|\*\*met\*\*|\bfloors\b")
    for path in _product_files():
        with open(path) as f:
            for k, line in enumerate(f, 1):
                assert not pattern.search(line), f"{path}:{k}: {line.strip()}"
