"""``denoise-bench report DIR``: a static HTML folder a person can look at.

``DIR/report/index.html`` with its images beside it (no network, no CDN): the run's summary
(command, machine, versions, seeds, commit), the leaderboard per task with its intervals
(sortable), time against error with the Pareto front and the frame budgets, per scene the
reference, the input and every filter's output with crops where the filters disagree most,
FLIP and relMSE error maps, per sequence the error over the frames and a strip of frames, and
the skipped and errored jobs. Images need a run made with ``--report`` (it keeps the outputs
of three frames per job of the first seed, :mod:`harness.report.outputs`).
"""

from harness.report.build import write_report

__all__ = ["write_report"]
