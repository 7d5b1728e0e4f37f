"""The README works as written: its Python snippet, its detect example, its links."""

from pathlib import Path
import re
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / 'README.md').read_text()


def _first_python_block() -> str:
    match = re.search(r'```python\n(.*?)```', README, re.S)
    assert match, 'the README has no Python block'
    return match.group(1)


def test_the_first_python_block_runs_verbatim_and_prints_what_the_readme_says():
    run = subprocess.run([sys.executable, '-c', _first_python_block()], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    promised = re.search(r'which prints `([^`]+)`', README).group(1)
    assert run.stdout.strip() == promised


def test_the_detect_example_prints_what_the_readme_shows():
    block = re.search(r'    pattern-locator detect (samples/\S+) --camera (samples/\S+)\n\n'
                      r'.*?The output:\n\n((?:    [^\n]*\n)+)', README, re.S)
    assert block, 'the README has no detect example with its output'
    image, camera, shown = block.groups()
    run = subprocess.run([sys.executable, '-m', 'pattern_locator.cli', 'detect', image,
                          '--camera', camera], cwd=ROOT, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    # Everything but the time taken must match.

    def strip_time(text: str) -> list:
        return [re.sub(r'in [0-9.]+ ms', 'in ... ms', line.strip())
                for line in text.splitlines() if line.strip()]
    assert strip_time(run.stdout) == strip_time(shown)


def test_every_file_the_readme_links_or_names_exists():
    links = re.findall(r'\]\(([^)#]+)\)', README)
    named = re.findall(r'`((?:samples|config|docs|launch)/[^`\s]+)`', README)
    for path in links + named:
        assert (ROOT / path).exists(), path
