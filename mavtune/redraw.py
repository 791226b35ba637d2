"""`mavtune report DIR`: a run folder's report, figures included, drawn again from its journal and config.json.

Nothing flies and the journal is opened read-only: the recorded rounds are replayed into a tuner (the engine is
deterministic, so it stands exactly where the run stood when it ended) and the report of that state is written.
result.json says how the run ended and is kept — only its note on the report changes; a run that died before
writing one (killed, crashed) gets one saying so. Whatever is refused is refused in one line, the folder as it was.
"""

from __future__ import annotations

import json
from contextlib import nullcontext
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape

from mavtune import interrupts
from mavtune.config import load_config
from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains
from mavtune.journal import Journal
from mavtune.plan import counted
from mavtune.runfolder import claimed
from mavtune.run import JOURNAL, REPORT, plan_of, run_summary, saved_config, write_json
from mavtune.search.interval import DRAWS
from mavtune.tuner import StageDone, Tuner, TuningResult

REPORT_NOTES = ("report_missing", "figures_missing")  # what result.json says of a report not (fully) written


class _Recorded:
    """The fleet of a replay: its rounds all come from the journal, so it never flies."""

    def __init__(self, size: int):
        self.size = size

    def fly(self, assignments: list[Gains], round_id: int) -> list[Flight]:
        raise MavtuneError(f"round {round_id} is not in the journal and a report flies nothing")

    def close(self) -> None:
        pass


def replay(out_dir: Path) -> tuple[TuningResult, Any, str, dict[str, Any] | None]:
    """The run recorded in `out_dir` as it stood when it ended: (result, config, status, result.json or None).

    The status is result.json's when it records the journal's rounds; without a result.json it is `finished`
    when the journal holds the whole run, else `error` (the run ended without writing one)."""
    if not out_dir.is_dir():
        raise MavtuneError(f"run folder {out_dir} {'is a file' if out_dir.exists() else 'does not exist'}")
    saved = saved_config(out_dir)
    if saved is None:
        raise MavtuneError(f"{out_dir} has no config.json: is it a mavtune run folder?")
    config = load_config(base=saved)
    summary = _read_result(out_dir / "result.json")
    with Journal(out_dir / JOURNAL, read_only=True) as book:
        book.bind(config.fingerprint())  # config.json must be the settings that flew these rounds
        recorded = len(book)
        said = summary.get("rounds") if summary is not None else None
        if summary is not None and said != recorded:
            raise MavtuneError(f"{out_dir / 'result.json'} records {said} rounds but the journal {recorded}: the run "
                               f"ended without writing it for the last rounds; `mavtune tune --out {out_dir}` "
                               "resumes the run and writes both (nothing was changed)")
        status = summary.get("status") if summary is not None else None
        settings = config.settings()
        tuner = Tuner(settings, _Recorded(settings.vehicles), book, stage_rounds=0,
                      draws=0 if status == "interrupted" else DRAWS)  # the intervals the run itself gave
        ended = "finished"
        try:
            tuner.run()
        except StageDone:
            ended = "stage"
        except MavtuneError:
            if len(tuner.rounds) < recorded:  # the journal does not replay: not the run the settings describe
                raise
            ended = "error"  # the run's own ending (e.g. no vehicle answered), replayed
    if status == "finished" and ended != "finished":
        raise MavtuneError(f"{out_dir / 'result.json'} says finished but the journal's {counted(recorded, 'round')} "
                           "do not end the run; nothing was changed")
    result = tuner.snapshot()
    log = (summary or {}).get("rounds_log") or []
    for rnd, logged in zip(result.rounds, log + [{}] * (len(result.rounds) - len(log))):
        rnd.replayed = bool(isinstance(logged, dict) and logged.get("replayed"))  # as the run that ended had it
    return result, config, status or ("finished" if ended == "finished" else "error"), summary


def redraw(out_dir: str | Path, surface: Path | None = None, console: Console | None = None) -> Path:
    """Write `out_dir/report.md` with its figures from the journal and config.json, flying nothing; result.json
    then says the report is whole. Returns the report's path."""
    out_dir, console = Path(out_dir), console or Console(emoji=False)
    with claimed(out_dir) if out_dir.is_dir() else nullcontext():  # replay names a missing folder
        return _redraw(out_dir, surface, console)


def _redraw(out_dir: Path, surface: Path | None, console: Console) -> Path:
    """redraw, with the run folder held."""
    from mavtune.report import write_run_report

    result, config, status, summary = replay(out_dir)
    if summary is None:  # the run never wrote result.json: one from the journal, saying so
        summary = run_summary(config, plan_of(config), result, None, status, None if status == "finished" else
                           "the run ended without writing result.json (killed or crashed?); written by "
                           "`mavtune report` from the journal", float("nan"), [], {})
        summary.pop("wall_s")
        with interrupts.deferred():
            write_json(out_dir / "result.json", summary)
    path = write_run_report(out_dir, result, config, surface=surface, status=status)
    for note in REPORT_NOTES:
        summary.pop(note, None)
    summary |= {"report": REPORT, "report_figures": True}
    with interrupts.deferred():
        write_json(out_dir / "result.json", summary)
    console.print(f"{escape(str(path))}: the {status} run, {counted(len(result.rounds), 'round')} (from the journal; "
                  "nothing flown)", highlight=False, soft_wrap=True)
    return path


def _read_result(path: Path) -> dict[str, Any] | None:
    """A run folder's result.json (None when there is none); an unreadable one is refused, never replaced."""
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise MavtuneError(f"{path} is unreadable ({exc}); it was left as it is") from None
    if not isinstance(data, dict) or not isinstance(data.get("rounds"), int):
        raise MavtuneError(f"{path} is not a mavtune result (no count of rounds); it was left as it is")
    return data
