"""Analysis: run directories, metrics, reports and plots."""
