"""Figures and reports of tuning runs and of the paper's reproduction (matplotlib loads only when drawing)."""


def write_run_report(*args, **kwargs):
    """Write a run folder's figures and report.md; see `mavtune.report.run_report.write_run_report`."""
    from mavtune.report.run_report import write_run_report as write

    return write(*args, **kwargs)


__all__ = ["write_run_report"]
