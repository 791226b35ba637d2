"""Figures and reports of tuning runs and of the paper's reproduction."""

from mavtune.report.run_report import write_run_report

__all__ = ["write_run_report"]
