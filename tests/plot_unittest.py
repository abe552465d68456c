#!/usr/bin/python3
"""Unit tests of scripts/plot.py's choices (what is drawn and how it is labelled), without pictures:
  /usr/bin/python3 tests/plot_unittest.py [PATH/TO/plot.py]   (default: ../scripts/plot.py beside tests/)
Run by ctest as plot_unittest."""
import importlib.util
import sys
import tempfile
import unittest
from pathlib import Path

DEFAULT_SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "plot.py"
SCRIPT = Path(sys.argv.pop(1)) if len(sys.argv) > 1 else DEFAULT_SCRIPT
spec = importlib.util.spec_from_file_location("plot", SCRIPT)
plot = importlib.util.module_from_spec(spec)
spec.loader.exec_module(plot)


def summary(ap, positives, curve=True):
    pr = {"average_precision": ap, "recall_at_100": 0.5, "positives": positives}
    if curve:
        pr["curve"] = [{"threshold": 0.9, "precision": 1.0, "recall": 0.5}]
    return {"evaluation": {"precision_recall": pr}}


class PrLegend(unittest.TestCase):
    def test_every_method_listed_no_detection_marked(self):
        entries = plot.pr_legend_entries({"gated": summary(0.0, 67, curve=False),
                                          "dird-seqslam-gated": summary(0.955, 67)}, "compare.json")
        labels = {name: label for name, label, _ in entries}
        self.assertEqual(set(labels), {"gated", "dird-seqslam-gated"})
        self.assertIn("no detection", labels["gated"])
        self.assertEqual(labels["dird-seqslam-gated"], "gated DIRD-SeqSLAM (AP 0.955, R@P100 0.500)")

    def test_no_positives_is_na_not_zero(self):
        entries = plot.pr_legend_entries({"full": summary(0.0, 0), "gated": summary(0.0, 0, curve=False)},
                                         "compare.json")
        for _, label, _ in entries:
            self.assertIn("AP n/a", label)
            self.assertNotIn("0.000", label)

    def test_no_ground_truth_left_out(self):
        self.assertEqual(plot.pr_legend_entries({"full": {"mode": "full"}}, "compare.json"), [])


class ShownMethod(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.dir = Path(self.tmp.name)

    def tearDown(self):
        self.tmp.cleanup()

    def runs(self, *names):
        for name in names:
            (self.dir / name).mkdir()

    def test_recommended_without_gated(self):
        self.runs("full", "dird-seqslam-gated")
        summaries = {"full": summary(0.9, 10), "dird-seqslam-gated": summary(0.5, 10)}
        self.assertEqual(plot.shown_method({"recommended": "dird-seqslam-gated"}, summaries, self.dir),
                         "dird-seqslam-gated")

    def test_best_defined_ap_when_no_recommendation(self):
        self.runs("full", "gated", "seqslam")
        summaries = {"full": summary(0.4, 10), "gated": summary(0.0, 10, curve=False),
                     "seqslam": summary(0.7, 10)}
        self.assertEqual(plot.shown_method({}, summaries, self.dir), "seqslam")

    def test_recommended_without_its_folder_falls_back(self):
        self.runs("full")
        summaries = {"full": summary(0.4, 10), "dird-seqslam-gated": summary(0.9, 10)}
        self.assertEqual(plot.shown_method({"recommended": "dird-seqslam-gated"}, summaries, self.dir), "full")
        self.assertIsNone(plot.shown_method({}, {"gated": summary(0.4, 10)}, self.dir))


class AggregateBars(unittest.TestCase):
    def test_bars_centred_on_their_run(self):
        runs = ["demo", "demo", "demo", "aliasing", "kitti", "kitti"]
        methods = ["full", "gated", "seqslam", "gated", "full", "seqslam"]
        x, width = plot.bar_positions(runs, methods)
        self.assertAlmostEqual(width, 0.8 / 3)
        self.assertAlmostEqual(sum(x[0:3]) / 3, 0.0)
        self.assertAlmostEqual(x[3], 1.0)  # the only bar of its run sits on its label
        self.assertAlmostEqual(sum(x[4:6]) / 2, 2.0)
        self.assertLess(x[0], x[1])
        self.assertLess(x[1], x[2])
        self.assertAlmostEqual(x[2] - x[1], width)


if __name__ == "__main__":
    unittest.main()
