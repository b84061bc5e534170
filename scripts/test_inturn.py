"""The in-turn timing harness (scripts/inturn.py, BENCHMARKS.md): run for real on tiny commands
(`sleep`, `python3 -c`), a dozen seconds in all: how many runs it makes and in which order, its
output's format, the pinning, bad arguments (exit 2) and the time bound (exit 3)."""

import os
import shlex
import subprocess
import sys
import tempfile
import time
import unittest
from pathlib import Path

INTURN = Path(__file__).resolve().with_name("inturn.py")


def inturn(*args, timeout=30):
    return subprocess.run([sys.executable, str(INTURN), *args], capture_output=True, text=True,
                          timeout=timeout)


def figures(stdout: str) -> dict:
    """{(who, figure): (unit, min, median, max)} from the figure lines of the output."""
    out = {}
    for line in stdout.splitlines():
        f = line.split()
        if f and f[0] in ("A", "B", "A/B") and len(f) == 6:
            out[(f[0], f[1])] = (f[2], float(f[3]), float(f[4]), float(f[5]))
    return out


def appender(path: Path, text: str) -> list:
    """A command that appends a line `text` to `path`."""
    return [sys.executable, "-c",
            f"open({str(path)!r}, 'a').write({text!r} + '\\n')"]


class Runs(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.tmp = Path(self.dir.name)

    def tearDown(self):
        self.dir.cleanup()

    def test_warm_ups_and_runs_are_all_made(self):
        log = self.tmp / "log"
        r = inturn("-n", "3", "--warmup", "2", "--", *appender(log, "A"))
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertEqual(log.read_text().split(), ["A"] * 5)
        self.assertEqual(r.stderr, "")

    def test_two_commands_run_in_turn_warm_ups_too(self):
        log = self.tmp / "log"
        b = shlex.join(appender(log, "B"))
        r = inturn("-n", "3", "--warmup", "1", "--vs", b, "--", *appender(log, "A"))
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertEqual(log.read_text().split(), ["A", "B"] * 4)

    def test_the_output_reads_as_documented(self):
        r = inturn("-n", "3", "--warmup", "0", "--vs", "sleep 0.1", "--", "sleep", "0.2")
        self.assertEqual(r.returncode, 0, r.stderr)
        f = figures(r.stdout)
        for who in ("A", "B"):
            for name, unit in (("wall", "s"), ("cpu", "s"), ("user", "s"), ("sys", "s"),
                               ("peak", "MiB")):
                self.assertEqual(f[(who, name)][0], unit, (who, name))
                lo, med, hi = f[(who, name)][1:]
                self.assertTrue(0 <= lo <= med <= hi, (who, name, lo, med, hi))
        self.assertTrue(0.15 <= f[("A", "wall")][2] <= 1.0, f[("A", "wall")])
        self.assertTrue(0.05 <= f[("B", "wall")][2] <= 1.0, f[("B", "wall")])
        self.assertLess(f[("A", "cpu")][2], 0.15)  # sleeping takes no cpu
        self.assertEqual(f[("A/B", "wall")][0], "-")
        self.assertTrue(1.2 <= f[("A/B", "wall")][2] <= 3.0, f[("A/B", "wall")])
        self.assertIn(("A/B", "cpu"), f)
        # the median as scripts/bench_residuals.sh reads it: the fifth field
        med = [ln.split()[4] for ln in r.stdout.splitlines()
               if ln.split()[:2] == ["A", "wall"]]
        self.assertEqual(float(med[0]), f[("A", "wall")][2])

    def test_nonzero_exit_codes_are_reported_not_acted_on(self):
        r = inturn("-n", "2", "--warmup", "0", "--vs", "true", "--", "sh", "-c", "exit 3")
        self.assertEqual(r.returncode, 0, r.stderr)
        exits = [ln for ln in r.stdout.splitlines() if ln.split()[:2] == ["A", "exit"]]
        self.assertEqual(len(exits), 1, r.stdout)
        self.assertIn("run 1: 3, run 2: 3", exits[0])
        self.assertFalse([ln for ln in r.stdout.splitlines() if ln.split()[:2] == ["B", "exit"]])

    @unittest.skipUnless(0 in os.sched_getaffinity(0), "CPU 0 is not available here")
    def test_pin_runs_the_child_on_those_cpus(self):
        kept = self.tmp / "kept"
        r = inturn("-n", "1", "--warmup", "0", "--pin", "0", "--keep-output", str(kept), "--",
                   sys.executable, "-c", "import os; print(sorted(os.sched_getaffinity(0)))")
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertEqual(kept.read_text().strip(), "[0]")
        self.assertIn("# cpus: 0 (pinned)", r.stdout)

    def test_output_is_discarded_by_default_kept_on_request_and_stdin_is_empty(self):
        child = [sys.executable, "-c", "import sys; print('child', 'out');"
                 " print('child', 'err', repr(sys.stdin.read()), file=sys.stderr)"]
        r = inturn("-n", "1", "--warmup", "0", "--", *child)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertNotIn("child out", r.stdout + r.stderr)
        self.assertNotIn("child err", r.stdout + r.stderr)
        kept = self.tmp / "kept"
        kept.write_text("before\n")
        r = inturn("-n", "1", "--warmup", "1", "--keep-output", str(kept), "--", *child)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertEqual(sorted(kept.read_text().splitlines()),
                         ["before"] + ["child err ''"] * 2 + ["child out"] * 2)


class BadCalls(unittest.TestCase):
    def assert_usage(self, r, words):
        self.assertEqual(r.returncode, 2, r.stdout + r.stderr)
        self.assertIn(words, r.stderr)
        self.assertNotIn("Traceback", r.stderr)
        self.assertEqual(r.stdout, "")

    def test_no_runs(self):
        self.assert_usage(inturn("-n", "0", "--", "true"), "RUNS must be at least 1")

    def test_no_command(self):
        self.assert_usage(inturn("-n", "2"), "no command")
        self.assert_usage(inturn("-n", "2", "--"), "no command")

    def test_bad_cpu_list(self):
        self.assert_usage(inturn("--pin", "x", "--", "true"), "not a CPU list")
        self.assert_usage(inturn("--pin", "4096", "--", "true"), "CPU 4096 not available")

    def test_a_command_that_cannot_start(self):
        self.assert_usage(inturn("--", "no-such-command-here"), "not found")
        self.assert_usage(inturn("--vs", "no-such-command-here", "--", "true"), "not found")
        self.assert_usage(inturn("--vs", "sleep '1", "--", "true"), "No closing quotation")


class Timeout(unittest.TestCase):
    def test_the_time_bound_kills_the_child_and_exits_3(self):
        t0 = time.monotonic()
        r = inturn("--timeout", "1", "--", "sleep", "5", timeout=10)
        took = time.monotonic() - t0
        self.assertEqual(r.returncode, 3, r.stdout + r.stderr)
        self.assertLess(took, 3.0)
        self.assertIn("timeout", r.stderr)
        self.assertIn("no counted run finished", r.stdout)

    def test_the_runs_that_finished_are_printed(self):
        r = inturn("-n", "20", "--warmup", "0", "--timeout", "1", "--", "sleep", "0.3",
                   timeout=10)
        self.assertEqual(r.returncode, 3, r.stdout + r.stderr)
        lo, med, hi = figures(r.stdout)[("A", "wall")][1:]
        self.assertTrue(0.25 <= med <= 1.0, med)


if __name__ == "__main__":
    unittest.main()
