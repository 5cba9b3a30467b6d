"""The package's examples are programs: each runs to its end on its virtual segment."""
import os
import subprocess
import sys

from conftest import EXAMPLES


def run(name, *args):
    p = subprocess.run(
        [sys.executable, os.path.join(EXAMPLES, name), *args], capture_output=True, text=True, timeout=120
    )
    assert p.returncode == 0, p.stderr
    return p.stdout


def test_basic_example():
    out = run("basic_example.py")
    assert "all slaves in OP: EK1100" in out
    assert "cycles with a short working counter: 0" in out
    assert "basic_example done" in out


def test_read_eeprom():
    lines = run("read_eeprom.py").splitlines()
    assert len(lines) == 64
    # Words 8 and 9: Beckhoff's vendor ID, 2.
    assert lines[8] == "0010:02|00" and lines[9] == "0012:00|00"


def test_read_sdo_info():
    out = run("read_sdo_info.py")
    assert "no SDO info for EK1100" in out
    assert "Idx: 0x1018" in out and "Idx: 0x6040" in out
    assert "Subindex 1; Type: 7; BitSize: 32" in out


def test_two_drives_csp():
    out = run("two_drives_csp.py")
    assert "'lock': 'locked'" in out
    lines = [l for l in out.splitlines() if "moved" in l]
    assert len(lines) == 2
    for l in lines:
        moved = int(l.split("moved ")[1].split(" ")[0])
        assert abs(moved - 65536) <= 16, l
        assert "OperationEnabled" in l


def test_the_python_snippets_of_the_readme_and_docs_run():
    root = os.path.dirname(os.path.dirname(EXAMPLES))
    blocks = []
    for doc in ["README.md", "docs/python.md"]:
        text = open(os.path.join(root, doc), encoding="utf-8").read()
        blocks += [b.split("```", 1)[0] for b in text.split("```python\n")[1:]]
    assert len(blocks) >= 2
    for code in blocks:
        exec(compile(code, "<snippet>", "exec"), {})
