"""Scoring: the benchmark's general metrics (metrics), region and stratified metrics (region_metrics),
the scoring rules that decide border and resolution (rules), bootstrap statistics (stats) and the
quality of uncertainty maps (uncertainty)."""
