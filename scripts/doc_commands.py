#!/usr/bin/env python3
"""Runs every command shown in README.md and docs/*.md (scripts/check_doc_commands.sh).

The commands are read from the markdown itself: the lines of shell code blocks (indented blocks
and fences without a language or with sh/bash/console) and the inline code spans that start like
a command (`pcr ...`, `target/release/...`, `bash scripts/...`, `cargo ...`) and carry an option.
Each one is run as written in a scratch directory (`pcr` on PATH, copies of configs/ and docs/),
unless scripts/doc_commands.toml says otherwise: extra arguments that make it small, concrete
commands for a synopsis with placeholders, the test that covers it, or why it is not run. A
command that fails, and an entry of the table that matches no command of the docs, fail the
check.
"""

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

try:
    import tomllib
except ImportError:  # Python < 3.11
    sys.exit("doc_commands.py needs Python 3.11 or later (tomllib)")
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SHELL_FENCES = {"", "sh", "bash", "shell", "console"}
INLINE_STARTS = ("pcr ", "target/release/", "bash scripts/", "cargo ", "make ", ".venv/")


@dataclass
class DocCommand:
    file: str
    line: int
    text: str

    def where(self) -> str:
        return f"{self.file}:{self.line}"


def normalize(cmd: str) -> str:
    return " ".join(cmd.split())


def strip_comment(line: str) -> str:
    """The line without its shell comment (`# ...` at the start or after a blank, unquoted)."""
    quote = None
    for i, c in enumerate(line):
        if quote:
            if c == quote:
                quote = None
        elif c in "\"'":
            quote = c
        elif c == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i]
    return line


def block_commands(lines, first_line, file):
    """Commands of one shell code block: comments dropped, `\\` continuations joined."""
    out, cur, start = [], "", None
    for k, raw in enumerate(lines):
        text = strip_comment(raw).rstrip()
        if not text.strip() and not cur:
            continue
        if start is None:
            start = first_line + k
        if text.endswith("\\"):
            cur += text[:-1] + " "
            continue
        cur += text
        if cur.strip():
            out.append(DocCommand(file, start, normalize(cur)))
        cur, start = "", None
    if cur.strip():
        out.append(DocCommand(file, start, normalize(cur)))
    return out


def is_list_line(line: str) -> bool:
    return re.match(r"^\s*([-*+]|\d+\.)\s", line) is not None


def extract(path: Path):
    """Every command of one markdown file, in order."""
    file = str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else path.name
    lines = path.read_text(encoding="utf-8").split("\n")
    cmds = []
    prose = []  # (line number, text) of lines outside code blocks
    i = 0
    in_list = False
    while i < len(lines):
        line = lines[i]
        fence = re.match(r"^\s*(```+|~~~+)\s*([\w+-]*)", line)
        if fence:
            marker, lang = fence.group(1), fence.group(2).lower()
            j = i + 1
            while j < len(lines) and not lines[j].strip().startswith(marker):
                j += 1
            if lang in SHELL_FENCES:
                cmds += block_commands(lines[i + 1 : j], i + 2, file)
            i = j + 1
            continue
        blank_before = i == 0 or not lines[i - 1].strip()
        if line.strip() and not line.startswith((" ", "\t")):
            in_list = is_list_line(line)
        if (
            line.startswith(("    ", "\t"))
            and line.strip()
            and blank_before
            and not in_list
        ):
            j = i
            while j < len(lines) and (
                lines[j].startswith(("    ", "\t")) or not lines[j].strip()
            ):
                j += 1
            block = [l[4:] if l.startswith("    ") else l.lstrip("\t") for l in lines[i:j]]
            cmds += block_commands(block, i + 1, file)
            i = j
            continue
        prose.append((i + 1, line))
        i += 1
    # Inline code spans (they may wrap over a line break).
    text = "\n".join(l for _, l in prose)
    numbers = [n for n, _ in prose]
    for m in re.finditer(r"(?<!`)`([^`]+)`(?!`)", text):
        span = normalize(m.group(1))
        if not span.startswith(INLINE_STARTS):
            continue
        if " -" not in span and " ctl " not in span:
            continue  # a name (`pcr calibrate`), not a command
        line = numbers[text.count("\n", 0, m.start())]
        cmds.append(DocCommand(file, line, span))
    cmds.sort(key=lambda c: c.line)
    return cmds


def doc_files():
    return [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))


KINDS = ("append", "run", "covered", "skip")


@dataclass
class Entry:
    """How one documented command (or every command matching a pattern) is checked."""

    key: str  # the doc command, or "re:<pattern>"
    spec: dict
    used: bool = False

    def matches(self, text: str) -> bool:
        if self.key.startswith("re:"):
            return re.fullmatch(self.key[3:], text) is not None
        return self.key == text


def load_table(path: Path):
    with open(path, "rb") as f:
        t = tomllib.load(f)
    entries, problems = [], []
    for k, e in enumerate(t.get("command", [])):
        where = f"{path.name}: command[{k}]"
        if ("doc" in e) == ("match" in e):
            problems.append(f"{where}: give exactly one of doc = ... or match = ...")
            continue
        key = normalize(e["doc"]) if "doc" in e else "re:" + e["match"]
        kinds = [x for x in KINDS if x in e]
        if len(kinds) > 1:
            problems.append(f"{where} ({key}): at most one of {', '.join(KINDS)}")
        if kinds and kinds[0] in ("append", "run", "covered") and not e.get("why"):
            problems.append(f"{where} ({key}): {kinds[0]} needs a why = ...")
        unknown = set(e) - {"doc", "match", "why", "in", *KINDS}
        if unknown:
            problems.append(f"{where}: unknown keys {sorted(unknown)}")
        if e.get("in", "scratch") not in ("scratch", "repo"):
            problems.append(f"{where}: in = \"scratch\" or \"repo\"")
        for c in as_list(e.get("covered", [])):
            problems += check_covered(c, where)
        entries.append(Entry(key, e))
    return t, entries, problems


def as_list(v):
    return v if isinstance(v, list) else [v]


def check_covered(name: str, where: str):
    """`path` (a script) or `path::function` (a test) must exist."""
    file, _, func = name.partition("::")
    p = ROOT / file
    if not p.is_file():
        return [f"{where}: covered by {name}: no file {file}"]
    if func and not re.search(rf"\bfn {re.escape(func)}\s*\(", p.read_text(encoding="utf-8")):
        return [f"{where}: covered by {name}: no fn {func} in {file}"]
    return []


class QtmServer:
    """A simulated QTM (`pcr qtm serve`) started on first use, for the commands that need one."""

    def __init__(self, command: str, cwd: Path, env: dict):
        self.command, self.cwd, self.env = command, cwd, env
        self.proc = None
        self.host = self.port = None

    def address(self):
        if self.proc is None:
            self.proc = subprocess.Popen(
                ["bash", "-c", "exec " + self.command],
                cwd=self.cwd,
                env=self.env,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                text=True,
            )
            line = self.proc.stdout.readline().strip()
            m = re.match(r"listening on (\S+):(\d+)$", line)
            if not m:
                raise RuntimeError(f"{self.command}: expected `listening on ADDR`, got {line!r}")
            self.host, self.port = m.group(1), m.group(2)
        return self.host, self.port

    def stop(self):
        if self.proc is not None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()


def make_scratch(table, pcr_bin: Path):
    d = Path(tempfile.mkdtemp(prefix="pcr-doc-commands-"))
    for sub in ("configs", "docs"):
        shutil.copytree(ROOT / sub, d / sub)
    (d / "bin").mkdir()
    (d / "bin" / "pcr").symlink_to(pcr_bin)
    for name, text in table.get("files", {}).items():
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_text(text)
    return d


def run_shell(cmd: str, cwd: Path, env: dict, timeout: float):
    t0 = time.monotonic()
    try:
        p = subprocess.run(
            ["bash", "-c", cmd],
            cwd=cwd,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            timeout=timeout,
        )
        return p.returncode, p.stdout, time.monotonic() - t0
    except subprocess.TimeoutExpired as e:
        out = e.stdout.decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
        return 124, out + f"\n(timed out after {timeout:.0f} s)", time.monotonic() - t0


def tail(text: str, n: int = 15) -> str:
    lines = text.rstrip().split("\n")
    return "\n".join("      | " + l for l in lines[-n:])


SAMPLE = """# Sample

Text with `pcr calibrate` (a name) and `pcr plan square
--side 40` (a command over a line break).

    pcr ik --input a.csv   # a comment
    # only a comment
    pcr residuals --data a.csv \\
        --out b.toml

- a list item

    indented list content, not code

```toml
name = "not a command"
```

```text
a diagram
```

```
pcr fk --input b.csv
```
"""


def self_test():
    """The extractor on SAMPLE, and the table's checks."""
    d = Path(tempfile.mkdtemp(prefix="pcr-doc-selftest-"))
    try:
        md = d / "sample.md"
        md.write_text(SAMPLE)
        got = [(c.line, c.text) for c in extract(md)]
        want = [
            (3, "pcr plan square --side 40"),
            (6, "pcr ik --input a.csv"),
            (8, "pcr residuals --data a.csv --out b.toml"),
            (24, "pcr fk --input b.csv"),
        ]
        assert got == want, got
        table = d / "t.toml"
        table.write_text(
            '[[command]]\ndoc = "x"\nappend = "--y"\n'
            '[[command]]\nmatch = "z.*"\ncovered = ["scripts/nothing.sh"]\nwhy = "w"\n'
        )
        _, entries, problems = load_table(table)
        assert len(problems) == 2, problems
        assert "needs a why" in problems[0], problems
        assert "no file scripts/nothing.sh" in problems[1], problems
        assert entries[1].matches("z 1") and not entries[1].matches("a z")
    finally:
        shutil.rmtree(d, ignore_errors=True)
    print("self-test: ok")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--list", action="store_true", help="list the commands found and exit")
    ap.add_argument("--pcr", type=Path, help="the pcr binary (release)")
    ap.add_argument("--table", type=Path, default=ROOT / "scripts" / "doc_commands.toml")
    ap.add_argument("--only", help="check only the commands containing this text")
    ap.add_argument("--keep", action="store_true", help="keep the scratch directory")
    ap.add_argument("--timeout", type=float, default=300.0, help="per command, s")
    ap.add_argument("--self-test", action="store_true", help="check the extractor and exit")
    args = ap.parse_args()
    if args.self_test:
        self_test()
        return 0
    cmds = [c for f in doc_files() for c in extract(f)]
    if args.list:
        for c in cmds:
            print(f"{c.where():28} {c.text}")
        return 0
    table, entries, problems = load_table(args.table)
    if problems:
        print("\n".join(problems))
        return 1
    if args.pcr is None:
        ap.error("--pcr is required")
    scratch = make_scratch(table, args.pcr.resolve())
    env = dict(os.environ)
    env.pop("PCR_LOG", None)
    env["PATH"] = f"{scratch / 'bin'}:{env['PATH']}"
    qtm = QtmServer(table.get("qtm_server", ""), scratch, env)
    counts = {"ran": 0, "reduced": 0, "covered": 0, "skipped": 0, "repeated": 0}
    failures = []
    done = set()
    t_all = time.monotonic()
    print(f"scratch directory: {scratch}")
    try:
        for setup in table.get("setup", []):
            rc, out, dt = run_shell(setup, scratch, env, args.timeout)
            print(f"setup {dt:5.1f} s  {setup}")
            if rc != 0:
                print(tail(out))
                failures.append(("setup", setup))
                return report(counts, failures, t_all)
        for c in cmds:
            if args.only and args.only not in c.text:
                continue
            entry = next((e for e in entries if e.matches(c.text)), None)
            spec = entry.spec if entry else {}
            if entry:
                entry.used = True
            label = f"{c.where():26} {c.text}"
            if "skip" in spec:
                counts["skipped"] += 1
                print(f"skip           {label}\n      not run: {spec['skip']}")
                continue
            if "covered" in spec:
                counts["covered"] += 1
                print(f"covered        {label}\n      by {', '.join(as_list(spec['covered']))}")
                continue
            if c.text in done:
                counts["repeated"] += 1
                print(f"ran above      {label}")
                continue
            done.add(c.text)
            if "append" in spec:
                runs = [c.text + " " + spec["append"]]
            elif "run" in spec:
                runs = as_list(spec["run"])
            else:
                runs = [c.text]
            cwd = ROOT if spec.get("in") == "repo" else scratch
            kind = "ran" if runs == [c.text] else "reduced"
            for r in runs:
                if "{qtm_" in r:
                    host, port = qtm.address()
                    r = r.replace("{qtm_host}", host).replace("{qtm_port}", port)
                rc, out, dt = run_shell(r, cwd, env, args.timeout)
                status = "ok" if rc == 0 else f"FAILED ({rc})"
                shown = label if r == c.text else f"{label}\n      as: {r}"
                print(f"{status:8} {dt:5.1f} s {shown}")
                if rc != 0:
                    print(tail(out))
                    failures.append((c.where(), r))
            counts[kind] += 1
        if not args.only:
            for e in entries:
                if not e.used:
                    stale = f"{e.key}: matches no command of the docs (stale entry)"
                    failures.append(("table", stale))
    finally:
        qtm.stop()
        if args.keep:
            print(f"kept {scratch}")
        else:
            shutil.rmtree(scratch, ignore_errors=True)
    return report(counts, failures, t_all)


def report(counts, failures, t0):
    print(
        f"\n{counts['ran']} run as written, {counts['reduced']} run in a stated form, "
        f"{counts['repeated']} repeated, {counts['covered']} covered by tests, "
        f"{counts['skipped']} not run; {time.monotonic() - t0:.0f} s"
    )
    for where, what in failures:
        print(f"FAILED {where}: {what}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
