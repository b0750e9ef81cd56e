"""The soak run shortened for CI: bench/soak.py's ``run_soak`` for 120 s of robot time (unknown association,
the default world, seed 0), sampled every 10 s from the in-process nodes.

Asserted: the SLAM covariance P stays symmetric positive definite at every sample, the map ends with the
world's 8 cylinders (each paired with a true one) and keeps them once complete, the SLAM position error is
under 2 cm at every sample once the map is complete, and soak.json and soak.png are written. The RSS is
recorded in soak.json, but neither it nor any timing is asserted (a shared, noisy machine); the memory
target needs the full run (docs/soak.md).

The SLAM error is not asserted from 20 s on: during the first loop, before every cylinder is mapped, it
peaks near 2 cm (13 mm or 20.5 mm at the 30 s sample, depending on which physics step the driver's first
command reaches nusim in; docs/soak.md).
"""

import importlib.util
import json
import math
import sys
from pathlib import Path

import pytest

SOAK_PY = Path(__file__).resolve().parents[2] / "bench" / "soak.py"
DURATION_S = 120.0
SAMPLE_PERIOD_S = 10.0
LANDMARKS_TRUE = 8
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def load_soak():
    """bench/soak.py as the module ``soak`` (bench/ is a folder of scripts, not a package)."""
    if "soak" not in sys.modules:
        spec = importlib.util.spec_from_file_location("soak", SOAK_PY)
        module = importlib.util.module_from_spec(spec)
        sys.modules["soak"] = module  # dataclasses look their module up while the file executes
        spec.loader.exec_module(module)
    return sys.modules["soak"]


@pytest.mark.slow
@pytest.mark.ros
def test_shortened_soak_keeps_p_map_and_accuracy(tmp_path):
    soak = load_soak()
    result = soak.run_soak(
        DURATION_S, tmp_path, association="unknown", seed=0, sample_period_s=SAMPLE_PERIOD_S, progress=False
    )
    samples = result.samples
    assert [s.sim_time_s for s in samples] == pytest.approx(
        [SAMPLE_PERIOD_S * (k + 1) for k in range(round(DURATION_S / SAMPLE_PERIOD_S))]
    )
    for s in samples:
        assert s.p_size == 3 + 2 * s.landmarks_mapped
        assert s.p_min_eigenvalue > 0.0, s
        assert s.p_asymmetry <= 1e-12, s
        assert s.rss_mb > 0.0
    complete = next(k for k, s in enumerate(samples) if s.landmarks_mapped == LANDMARKS_TRUE)
    for s in samples[complete:]:
        assert s.landmarks_mapped == s.landmarks_paired == LANDMARKS_TRUE, s
        assert math.isfinite(s.slam_error_m) and s.slam_error_m < 0.02, s
    assert samples[-1].landmarks_mapped == LANDMARKS_TRUE
    assert result.metrics["landmarks_spurious"] == result.metrics["landmarks_duplicate"] == 0
    assert {t.name: t.passed for t in result.targets} == {
        "P symmetric positive definite": True,
        "map keeps its landmarks": True,
        "memory flat": None,  # not judged on a 2-minute run
        "SLAM error under 2 cm": True,
    }

    report = json.loads(result.json_path.read_text())
    assert len(report["samples"]) == len(samples)
    assert report["summary"]["landmarks_mapped_end"] == LANDMARKS_TRUE
    assert report["summary"]["rss_end_mb"] == pytest.approx(samples[-1].rss_mb)
    assert report["summary"]["rss_5min_mb"] is None  # the run ends before the 5 min reference
    assert [t["verdict"] for t in report["targets"]] == ["PASS", "PASS", "n/a", "PASS"]
    assert result.png_path.read_bytes().startswith(PNG_MAGIC)
    assert (tmp_path / "metrics.json").is_file()
