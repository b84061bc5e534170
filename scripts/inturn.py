#!/usr/bin/env python3
"""Times a command, or two commands in turn, the way BENCHMARKS.md's timings are taken.

    scripts/inturn.py [-n RUNS] [--warmup W] [--pin CPUS] [--timeout S] [--vs 'COMMAND_B']
                      [--keep-output FILE] -- COMMAND [ARG ...]

Runs COMMAND (A) RUNS times after W warm-up runs that are not counted. With `--vs`, COMMAND_B
(B, one string split like a shell would split it, without expanding anything) runs too, in turn
with A: A B A B ..., the warm-ups likewise. Each run is measured on its own: wall time from start
to reap, and the finished child's user and system CPU time and peak resident memory (from
wait4's rusage); cpu = user + system. With `--vs` the ratios A/B are taken pair by pair (the
i-th run of A against the i-th of B, which ran right after it), so that a drift of the machine's
speed over the call cancels, and their min / median / max are printed. The peak is the
kernel's count for the child process, which starts from the harness's own resident size at the
fork (12-16 MiB): a smaller peak does not show.

The children's stdin is /dev/null, their output is discarded (`--keep-output FILE` appends both
streams to FILE instead), they run in a new session (process group) of their own and, with
`--pin 1` or `--pin 0,1`, on those CPUs only. Their exit codes are reported, never acted on.

Output (stdout): `#` lines (the settings, the CPUs, one line per run), then one line per figure:

    A wall s    min median max
    A cpu s     ...
    A user s    ...
    A sys s     ...
    A peak MiB  ...
    B ...                   (with --vs)
    A/B wall -  min median max
    A/B cpu -   ...

that is: who, figure, unit, min, median, max (so `awk '$1 == "A" && $2 == "wall" {print $5}'`
reads the median wall of A).

Exit status: 0 when every run was made (whatever the commands' exit codes); 2 on bad arguments
or a command that cannot start; 3 when `--timeout` (the whole call, default 600 s) was reached:
the running child's process group is killed and the figures of the runs that finished are
printed. Standard library only, Linux (sched_setaffinity, wait4).
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import signal
import statistics
import subprocess
import sys
import time

FIGURES = (("wall", "s"), ("cpu", "s"), ("user", "s"), ("sys", "s"), ("peak", "MiB"))
RATIOS = ("wall", "cpu")


class Usage(Exception):
    """A bad argument or a command that cannot start: exit 2."""


class Interrupted(Exception):
    """SIGINT or SIGTERM to the harness."""

    def __init__(self, signum):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def parse_cpus(text: str) -> list[int]:
    """`1`, `0,1`, `0-3` or `0,2-3` -> the sorted CPU numbers; Usage on anything else."""
    cpus = set()
    for part in text.split(","):
        part = part.strip()
        lo, dash, hi = part.partition("-")
        try:
            first = int(lo)
            last = int(hi) if dash else first
        except ValueError:
            raise Usage(f"--pin {text!r}: not a CPU list (e.g. 1, 0,1 or 0-1)") from None
        if first < 0 or last < first:
            raise Usage(f"--pin {text!r}: bad CPU range {part!r}")
        cpus.update(range(first, last + 1))
    available = os.sched_getaffinity(0)
    missing = sorted(cpus - available)
    if missing:
        raise Usage(f"--pin {text!r}: CPU {','.join(map(str, missing))} not available "
                    f"(available: {','.join(map(str, sorted(available)))})")
    return sorted(cpus)


def check_startable(cmd: list[str], what: str) -> None:
    """Usage unless the program of `cmd` exists and is executable (as Popen would find it)."""
    if not cmd:
        raise Usage(f"{what}: empty command")
    if shutil.which(cmd[0]) is None:
        if os.sep in cmd[0]:
            raise Usage(f"{what}: {cmd[0]!r} is not an executable file")
        raise Usage(f"{what}: {cmd[0]!r} not found on PATH")


def parse_args(argv: list[str]):
    ap = argparse.ArgumentParser(
        prog="inturn.py",
        usage="%(prog)s [-n RUNS] [--warmup W] [--pin CPUS] [--timeout S] [--vs 'COMMAND_B'] "
              "[--keep-output FILE] -- COMMAND [ARG ...]",
        description=__doc__.split("\n")[0])
    ap.add_argument("-n", "--runs", type=int, default=5, metavar="RUNS",
                    help="counted runs of each command (default 5)")
    ap.add_argument("--warmup", type=int, default=1, metavar="W",
                    help="uncounted runs of each command first (default 1)")
    ap.add_argument("--pin", metavar="CPUS", help="run the children on these CPUs: 1, 0,1, 0-1")
    ap.add_argument("--timeout", type=float, default=600.0, metavar="S",
                    help="bound on the whole call, s (default 600): exit 3 when reached")
    ap.add_argument("--vs", metavar="COMMAND_B",
                    help="a second command (one string, split with shlex), run in turn with A")
    ap.add_argument("--keep-output", metavar="FILE",
                    help="append the children's stdout and stderr to FILE (default: discarded)")
    # Everything after the first `--` is the command, untouched by argparse.
    if "--" in argv:
        k = argv.index("--")
        opts, cmd = argv[:k], argv[k + 1:]
    else:
        opts, cmd = argv, []
    ap.add_argument("command", nargs="*", help=argparse.SUPPRESS)
    args = ap.parse_args(opts)
    args.command = args.command + cmd
    try:
        if not args.command:
            raise Usage("no command given (usage: inturn.py [options] -- COMMAND [ARG ...])")
        if args.runs < 1:
            raise Usage(f"-n {args.runs}: RUNS must be at least 1")
        if args.warmup < 0:
            raise Usage(f"--warmup {args.warmup}: W must be 0 or more")
        if not 0 < args.timeout <= 1e7:
            raise Usage(f"--timeout {args.timeout:g}: S must be more than 0 and at most 1e7")
        args.cpus = parse_cpus(args.pin) if args.pin is not None else None
        if args.vs is not None:
            try:
                args.b = shlex.split(args.vs)
            except ValueError as e:
                raise Usage(f"--vs {args.vs!r}: {e}") from None
            if not args.b:
                raise Usage("--vs: empty command")
        else:
            args.b = None
        check_startable(args.command, "COMMAND")
        if args.b is not None:
            check_startable(args.b, "--vs")
        if args.keep_output is not None:
            try:
                open(args.keep_output, "ab").close()
            except OSError as e:
                raise Usage(f"--keep-output {args.keep_output!r}: {e.strerror}") from None
    except Usage as e:
        ap.exit(2, f"{ap.prog}: error: {e}\n")
    return args


class Runner:
    """Starts and reaps the children; one alarm bounds the whole call."""

    def __init__(self, args):
        self.cpus = args.cpus
        self.keep = args.keep_output
        self.timed_out = False
        self.child = None  # the running child's pid (= its process group)
        self.deadline = time.monotonic() + args.timeout

    def arm(self, seconds: float) -> None:
        signal.signal(signal.SIGALRM, self._alarm)
        signal.signal(signal.SIGTERM, self._interrupt)
        signal.setitimer(signal.ITIMER_REAL, seconds)

    def _alarm(self, signum, frame):
        self.timed_out = True
        self.kill()

    def _interrupt(self, signum, frame):
        raise Interrupted(signum)

    def kill(self) -> None:
        if self.child is not None:
            try:
                os.killpg(self.child, signal.SIGKILL)
            except ProcessLookupError:
                pass

    def reap(self) -> None:
        """Kills and reaps the running child, if any (on an interrupt)."""
        if self.child is not None:
            self.kill()
            try:
                os.waitpid(self.child, 0)
            except ChildProcessError:
                pass
            self.child = None

    def run(self, cmd: list[str]):
        """One run of `cmd`: a dict of the figures and the exit code, or None when killed."""
        if self.timed_out:
            return None
        cpus = self.cpus
        preexec = (lambda: os.sched_setaffinity(0, cpus)) if cpus is not None else None
        out = open(self.keep, "ab") if self.keep is not None else subprocess.DEVNULL
        try:
            t0 = time.monotonic()
            try:
                p = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=out, stderr=out,
                                     start_new_session=True, preexec_fn=preexec)
            except (OSError, subprocess.SubprocessError) as e:
                raise Usage(f"cannot start {shlex.join(cmd)!r}: {e}") from None
            self.child = p.pid
            if self.timed_out:  # the alarm rang while it was starting
                self.kill()
            _, status, ru = os.wait4(p.pid, 0)
            wall = time.monotonic() - t0
            self.child = None
            p.returncode = os.waitstatus_to_exitcode(status)
        finally:
            if out is not subprocess.DEVNULL:
                out.close()
        if self.timed_out:
            return None
        user, sys_ = ru.ru_utime, ru.ru_stime
        return {"wall": wall, "cpu": user + sys_, "user": user, "sys": sys_,
                "peak": ru.ru_maxrss / 1024.0, "rc": p.returncode}


def fmt(x: float, unit: str) -> str:
    return f"{x:.1f}" if unit == "MiB" else f"{x:.3f}"


def spread(values: list[float]):
    return min(values), statistics.median(values), max(values)


def summary(results: dict[str, list[dict]]) -> list[str]:
    lines = []
    for who, runs in results.items():
        if not runs:
            lines.append(f"# {who}: no counted run finished")
            continue
        for name, unit in FIGURES:
            lo, med, hi = spread([r[name] for r in runs])
            lines.append(f"{who:<3} {name:<4} {unit:<3}  "
                         f"{fmt(lo, unit)} {fmt(med, unit)} {fmt(hi, unit)}")
    if "B" in results:
        pairs = list(zip(results["A"], results["B"]))
        for name in RATIOS:
            ratios = [a[name] / b[name] for a, b in pairs if b[name] > 0]
            if ratios:
                lo, med, hi = spread(ratios)
                lines.append(f"A/B {name:<4} -    {lo:.3f} {med:.3f} {hi:.3f}")
            else:
                lines.append(f"A/B {name:<4} -    nan nan nan")
    return lines


def exit_codes(all_runs: dict[str, list[tuple[str, dict]]]) -> list[str]:
    lines = []
    for who, runs in all_runs.items():
        bad = [f"run {tag}: {r['rc']}" for tag, r in runs if r["rc"] != 0]
        if bad:
            lines.append(f"{who:<3} exit codes not 0 ({len(bad)} of {len(runs)} runs): "
                         + ", ".join(bad))
    return lines


def main(argv: list[str]) -> int:
    args = parse_args(argv)
    cmds = {"A": args.command}
    if args.b is not None:
        cmds["B"] = args.b
    runner = Runner(args)
    print(f"# A: {shlex.join(args.command)}")
    if args.b is not None:
        print(f"# B: {shlex.join(args.b)}")
    turns = ", in turn: A B A B ..." if args.b is not None else ""
    print(f"# {args.runs} runs after {args.warmup} warm-up{turns}")
    if args.cpus is not None:
        print(f"# cpus: {','.join(map(str, args.cpus))} (pinned)")
    else:
        print(f"# cpus: {','.join(map(str, sorted(os.sched_getaffinity(0))))} (not pinned)")
    sys.stdout.flush()

    counted: dict[str, list[dict]] = {who: [] for who in cmds}
    every: dict[str, list[tuple[str, dict]]] = {who: [] for who in cmds}
    schedule = [(f"w{i + 1}", False) for i in range(args.warmup)]
    schedule += [(f"{i + 1}", True) for i in range(args.runs)]
    stopped = None
    runner.arm(args.timeout)
    try:
        for tag, counts in schedule:
            for who, cmd in cmds.items():
                r = runner.run(cmd)
                if r is None:  # killed, or not started: the time is up
                    stopped = f"{who} run {tag}"
                    break
                every[who].append((tag, r))
                if counts:
                    counted[who].append(r)
                print(f"# {who} {tag:>3}  wall {r['wall']:.3f} s  cpu {r['cpu']:.3f} s  "
                      f"user {r['user']:.3f} s  sys {r['sys']:.3f} s  peak {r['peak']:.1f} MiB"
                      f"  exit {r['rc']}", flush=True)
            if stopped:
                break
    except (Interrupted, KeyboardInterrupt) as e:
        signal.setitimer(signal.ITIMER_REAL, 0)
        runner.reap()
        print("\n".join(summary(counted) + exit_codes(every)), flush=True)
        by = e if isinstance(e, Interrupted) else "SIGINT"
        print(f"inturn.py: stopped by {by}; the figures above are of the runs that finished",
              file=sys.stderr)
        return 128 + (e.signum if isinstance(e, Interrupted) else signal.SIGINT)
    signal.setitimer(signal.ITIMER_REAL, 0)
    print("\n".join(summary(counted) + exit_codes(every)), flush=True)
    if stopped:
        done = ", ".join(f"{who} {len(runs)} of {args.runs}" for who, runs in counted.items())
        print(f"inturn.py: timeout: {args.timeout:g} s reached at {stopped} (the running child's "
              f"process group killed); counted runs finished: {done}", file=sys.stderr)
        return 3
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except Usage as e:
        print(f"inturn.py: error: {e}", file=sys.stderr)
        sys.exit(2)
