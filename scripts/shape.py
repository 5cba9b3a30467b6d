#!/usr/bin/env python3
"""The master's shape, measured (docs/architecture.md, "The master's shape"): public fields of
each public struct, public methods of each type and trait (the `Master`'s with its impl blocks
and files), and how many errors are built from free text. Reads crates/master/src; prints a Markdown table.

    python3 scripts/shape.py
"""
import re
import sys
from pathlib import Path

root = Path(__file__).resolve().parent.parent / "crates" / "master" / "src"
files = sorted(root.rglob("*.rs"))


def code(text):
    """The text without comments and without test modules."""
    out = []
    for line in text.splitlines():
        if line.strip().startswith("#[cfg(test)]"):
            break
        out.append(line.split("//")[0])
    return "\n".join(out)


def blocks(text, head):
    """The bodies of the blocks whose header matches `head`."""
    for m in re.finditer(head, text):
        start = text.index("{", m.end() - 1)
        depth, i = 0, start
        while i < len(text):
            if text[i] == "{":
                depth += 1
            elif text[i] == "}":
                depth -= 1
                if depth == 0:
                    yield m, text[start + 1 : i]
                    break
            i += 1


structs = {}
methods = {}  # public type -> public methods over all its inherent impl blocks
master_impls, master_files = 0, set()
free_text = 0
for f in files:
    t = code(f.read_text())
    for m, body in blocks(t, r"pub struct (\w+)(?:<[^>{]*>)?\s*\{"):
        # Fields at the struct's own depth only.
        depth, pub = 0, 0
        for line in body.splitlines():
            if depth == 0 and re.match(r"\s*pub\s+\w+\s*:", line):
                pub += 1
            depth += line.count("{") + line.count("(") - line.count("}") - line.count(")")
        structs[m.group(1)] = max(structs.get(m.group(1), 0), pub)
    # Inherent impls (not `impl Trait for`), by the type's last path segment.
    for m, body in blocks(t, r"(?m)^impl(?:<[^>{]*>)?\s+((?:\w+::)*(\w+))(?:<[^>{]*>)?\s*\{"):
        name = m.group(2)
        methods[name] = methods.get(name, 0) + len(re.findall(r"^\s{4}pub fn ", body, re.M))
        if name == "Master":
            master_impls += 1
            master_files.add(f.relative_to(root))
    # The parts' accessors, made by a macro (part.rs): one method of `Master` each.
    methods["Master"] = methods.get("Master", 0) + len(re.findall(r"^part!\(", t, re.M))
    free_text += len(re.findall(r"MasterError::Config\((?:format!|\"|String)|MasterError::slave\(|SlaveError::Other\(", t))
    for m, body in blocks(t, r"pub trait (\w+)(?:<[^>{]*>)?[^{]*\{"):
        methods[m.group(1)] = len(re.findall(r"^\s{4}fn ", body, re.M))

print("| measure | value |")
print("|---|---|")
print(f"| `Master`: public fields | {structs.get('Master', 0)} |")
print(f"| `Master`: impl blocks / files / public methods | {master_impls} / {len(master_files)} / {methods.get('Master', 0)} |")
print(f"| `Slave`: public fields | {structs.get('Slave', 0)} |")
wide = sorted(((n, c) for n, c in structs.items() if c > 12), key=lambda x: -x[1])
print(f"| public structs with more than 12 public fields | {', '.join(f'`{n}` ({c})' for n, c in wide) or 'none'} |")
many = sorted(((n, c) for n, c in methods.items() if c > 12), key=lambda x: -x[1])
print(f"| types and traits with more than 12 public methods | {', '.join(f'`{n}` ({c})' for n, c in many) or 'none'} |")
print(f"| errors built from free text (`Config(…)`, `slave(…)`, `Other(…)` sites) | {free_text} |")
sys.exit(0)
