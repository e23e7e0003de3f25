"""Visual outputs: Rerun dashboards (live and recorded) and the static HTML fatigue report."""
