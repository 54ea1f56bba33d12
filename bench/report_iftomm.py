"""The IFToMM multibody benchmark section of the strata benchmark report (used by
bench/report.py): results of kind "iftomm" that bench/iftomm.py writes, one row per
(problem, settings) with the deviation from the model file's reference and the times.

The IFToMM library (iftomm-multibody.org) publishes, per problem, submitted solutions with
their error and CPU time; none of those entries were available when this section was
written, so the table has no "published" column: a results row may carry a "published"
object {"error": .., "cpu_seconds": .., "source": ..} and it is then shown beside strata's.
"""
from __future__ import annotations

from report_common import NOT_MEASURED, Run, f_e, table


class IftommSection:
    """Mixin of Report."""

    def iftomm_section(self, runs: list[Run]) -> None:
        self.w("## IFToMM multibody benchmarks: `strata simulate` on models/iftomm/")
        self.w()
        mine = [r for r in runs if r.kind == "iftomm"]
        if not mine:
            self.w(f"{NOT_MEASURED}: no `iftomm` results; run `python3 bench/iftomm.py`.")
            self.w()
            return
        r = max(mine, key=lambda x: x.date)
        self.consumed.update(x.path for x in mine)
        self.w("Each problem's model file carries its reference values and where they come "
               "from (its `description` and `reference.source`): the published reference "
               "where it was available (Andrews: the Test Set for IVP Solvers), otherwise a "
               "closed form (simple pendulum, N-four-bar: the pendulum equation of the "
               "parallelogram branch) or an independent tightly converged solution (Bricard: "
               "the same mechanism without the redundant joint; flyball governor and "
               "slider-crank: both formulations at Newton tolerances 1e-10/1e-12). The "
               "library's own reference data files and its table of submitted solutions "
               "(error, CPU time of other codes) were not available here, so no published "
               "entries are shown. Error: the largest deviation from the reference values at "
               "the reference time (m or rad). Times: wall-clock seconds of the whole run "
               "as the summary prints them (solver and assembly parts), on the machine named "
               "below; they are reported, not tested.")
        self.w()
        rows = []
        for row in r.rows:
            err = row.get("reference_error")
            tol = row.get("reference_tolerance") or 1e-3
            if not row.get("complete"):
                status = f"stopped at t = {row.get('t_reached', 0):.4g} s"
            elif err is not None and err > tol:
                status = "complete, warns"
            elif row.get("warnings"):
                status = "complete, warns"
            else:
                status = "complete"
            pub = row.get("published") or {}
            steps = row.get("steps")
            rows.append([
                str(row.get("problem")), f"`{row.get('settings')}`", status,
                f_e(err) if err is not None and row.get("complete") else "–",
                f"{row['wall_seconds']:.3f}" if "wall_seconds" in row else "–",
                (f"{row['solver_seconds']:.3f} / {row['assembly_seconds']:.3f}"
                 if "solver_seconds" in row else "–"),
                f"{steps} ({row.get('rejected', 0)})" if steps is not None else "–",
                (f"{row['stabilized_from']:.3g}" if "stabilized_from" in row else "–"),
                (f_e(row["energy_change"]) if "energy_change" in row else "–"),
                (f"{f_e(pub.get('error'))}, {pub.get('cpu_seconds')} s" if pub else "–"),
            ])
        self.w(table(["problem", "settings", "result", "error", "wall s", "solver / assembly s",
                      "steps (rejected)", "stabilized from t [s]", "energy change J",
                      "published"], rows, right_from=3))
        self.caption("Table: copied from the rows (\"warns\": the summary and status.json "
                     "carry a warning: reference missed or energy drift).", [r])
