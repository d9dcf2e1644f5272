"""bench/run_all's arithmetic and order: what `--repeat` and `--before` put in the table.

The benchmarks themselves are not run here (they are measured by bench/run_all itself, never in a
test); `measure` is a function that returns fixed rows, so every assertion is exact.
"""
import contextlib
import importlib.machinery
import importlib.util
import io
import os
import statistics
import unittest

SOURCE_DIR = os.environ.get("TEMPOKEY_SOURCE_DIR",
                            os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))


def load_run_all():
    path = os.path.join(SOURCE_DIR, "bench", "run_all")
    loader = importlib.machinery.SourceFileLoader("run_all", path)
    spec = importlib.util.spec_from_loader("run_all", loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


run_all = load_run_all()


def row(id, value, peer=None, figure=None):
    return run_all.Row(id, figure or id, "<= 60", value, "ms", "lower", "peer", peer)


class Recorder:
    """Returns the next of `figures[build]` each call, and records the order of the builds."""

    def __init__(self, figures):
        self.figures = {build: list(values) for build, values in figures.items()}
        self.calls = []

    def __call__(self, build):
        self.calls.append(build)
        value, peer = self.figures[build].pop(0)
        return [row("tolerance", value, peer, figure=f"tolerance ({build} {value})")]


class MedianTest(unittest.TestCase):
    def test_agrees_with_the_standard_library_for_odd_and_even_counts(self):
        for values in ([3.0], [5.0, 1.0], [2.0, 9.0, 4.0], [7.0, 1.0, 3.0, 8.0], [1.0] * 6):
            self.assertEqual(run_all.median(values), statistics.median(values))


class MeasureGroupTest(unittest.TestCase):
    def test_the_builds_alternate_so_that_each_goes_first_in_half_the_runs(self):
        measure = Recorder({"A": [(1, 1)] * 4, "B": [(1, 1)] * 4})
        run_all.measure_group(measure, "A", "B", 4)
        self.assertEqual(measure.calls, ["A", "B", "B", "A", "A", "B", "B", "A"])

    def test_one_run_keeps_its_rows_and_gives_them_the_before(self):
        measure = Recorder({"A": [(80.0, 64.0)], "B": [(84.0, 70.0)]})
        [r] = run_all.measure_group(measure, "A", "B", 1)
        self.assertEqual((r.value, r.peer_value, r.before), (80.0, 64.0, 84.0))
        self.assertEqual(r.spread, [])

    def test_several_runs_give_medians_and_the_range_of_the_per_run_ratios(self):
        measure = Recorder({"A": [(80.0, 60.0), (100.0, 75.0), (90.0, 70.0)],
                            "B": [(100.0, 0), (80.0, 0), (90.0, 0)]})
        [r] = run_all.measure_group(measure, "A", "B", 3)
        self.assertEqual((r.value, r.peer_value, r.before), (90.0, 70.0, 90.0))
        self.assertEqual(sorted(r.spread), [0.8, 1.0, 1.25])
        # The figure's text is that of the run whose figure is the median.
        self.assertEqual(r.figure, "tolerance (A 90.0)")

    def test_without_a_before_the_runs_are_this_build_alone(self):
        measure = Recorder({"A": [(3.0, None), (1.0, None), (2.0, None)]})
        [r] = run_all.measure_group(measure, "A", None, 3)
        self.assertEqual(measure.calls, ["A", "A", "A"])
        self.assertEqual((r.value, r.peer_value, r.before), (2.0, None, None))


class TableTest(unittest.TestCase):
    def printed(self, rows, before):
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            run_all.print_table(rows, before)
        return out.getvalue().splitlines()[-1]

    def test_the_change_column_shows_the_range_only_over_several_runs(self):
        r = row("tolerance", 90.0, 70.0)
        r.before = 90.0
        self.assertTrue(self.printed([r], True).endswith("| 90.0 | 1.00x |"))
        r.spread = [0.8, 1.0, 1.25]
        self.assertTrue(self.printed([r], True).endswith("| 90.0 | 1.00x (0.80-1.25) |"))


if __name__ == "__main__":
    unittest.main()
