"""Figures and reports of tuning runs (`write_run_report`) and the claims of the paper's reproduction."""

from mavtune.report.run_report import write_run_report

__all__ = ["write_run_report"]
