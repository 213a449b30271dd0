"""The job pool of ``texsyn serve``: a bounded queue, one process per running job, cancel and timeouts.

Each job runs its steps (:mod:`texsyn.web.requests`) as processes of their own, started in a
new session so that a cancel or a timeout stops the whole process group: SIGTERM first (the
command line then removes its temporary files and exits 143), SIGKILL half a second later
if it is still there. At most ``workers`` jobs run at once, each with ``cores / workers``
BLAS and numba threads (same bytes on any thread count: ``docs/determinism.md``); the
others wait in a queue of at most ``queue_limit``, and each knows its position. The server's
event loop only waits on pipes: no work ever blocks it (``docs/web.md``, "Jobs").
"""

from __future__ import annotations

import asyncio
import contextlib
import html
import json
import os
import secrets
import signal
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

from .requests import JobPlan

__all__ = ["FINAL_STATES", "Job", "JobManager", "QueueFullError"]

#: states a job does not leave
FINAL_STATES = ("done", "failed", "cancelled")
#: seconds between SIGTERM and SIGKILL when a job is stopped
KILL_GRACE = 0.5
#: jobs remembered at most (the oldest finished ones and their files are removed first)
MAX_JOBS_KEPT = 200


class QueueFullError(RuntimeError):
    """The queue holds ``queue_limit`` jobs already."""


@dataclass
class Job:
    """One job: its plan, its state and what its processes reported."""

    id: str
    plan: JobPlan
    folder: Path
    state: str = "queued"
    position: int = 0
    progress: dict | None = None
    step: int = 0
    error: str | None = None
    warning: str | None = None
    metrics: dict | None = None
    created: float = field(default_factory=time.monotonic)
    started: float | None = None
    finished: float | None = None
    process: asyncio.subprocess.Process | None = None
    cancel_requested: bool = False
    version: int = 0
    changed: asyncio.Event = field(default_factory=asyncio.Event)

    def touch(self) -> None:
        """Wake whoever waits for a change of this job (the event streams)."""
        self.version += 1
        self.changed.set()
        self.changed = asyncio.Event()

    def public(self, token_query: str = "") -> dict:
        """The job as the page sees it (no server path)."""
        now = time.monotonic()
        files = {}
        if self.state == "done" or self.state == "running":  # a finished step's files already show
            for key, item in self.plan.files.items():
                finished = self.state == "done" or item.step < self.step
                if finished and (self.folder / item.filename).is_file():
                    files[key] = {
                        "url": f"/api/jobs/{self.id}/files/{key}{token_query}",
                        "name": item.download_name,
                    }
        return {
            "id": self.id,
            "mode": self.plan.mode,
            "label": self.plan.label,
            "state": self.state,
            "position": self.position,
            "progress": self.progress,
            "step": self.step,
            "steps": len(self.plan.steps),
            "error": self.error,
            "warning": self.warning,
            "seed": self.plan.seed,
            "command_line": self.plan.command_line,
            "exemplar": self.plan.exemplar.public(),
            "metrics": self.metrics,
            "files": files,
            "elapsed": round((self.finished or now) - self.started, 2) if self.started else 0.0,
        }


class JobManager:
    """Queue and run jobs; every method is called from the server's event loop.

    Parameters
    ----------
    folder : Path
        Where each job gets a folder of its own (the server's temporary folder).
    workers : int
        Jobs running at once.
    queue_limit : int
        Jobs waiting at most.
    timeout : float
        Seconds a job may run.
    """

    def __init__(self, folder: Path, workers: int, queue_limit: int, timeout: float):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.workers = max(1, int(workers))
        self.queue_limit = max(0, int(queue_limit))
        self.timeout = float(timeout)
        self.jobs: dict[str, Job] = {}
        self.waiting: deque[Job] = deque()
        self.running: set[str] = set()
        self.tasks: set[asyncio.Task] = set()
        cores = os.cpu_count() or 1
        self.threads = max(1, cores // self.workers)

    # ------------------------------------------------------------------ queue
    def submit(self, plan: JobPlan) -> Job:
        """Queue a planned job; :class:`QueueFullError` when the queue is full."""
        if len(self.waiting) >= self.queue_limit and len(self.running) >= self.workers:
            raise QueueFullError(
                f"the queue is full ({self.queue_limit} jobs waiting, {self.workers} running); "
                "try again when one has finished"
            )
        self._forget_old()
        job_id = "j" + secrets.token_hex(8)
        folder = self.folder / job_id
        folder.mkdir()
        job = Job(job_id, plan, folder)
        self.jobs[job_id] = job
        self.waiting.append(job)
        self._pump()
        return job

    def cancel(self, job: Job) -> None:
        """Stop a job: take it out of the queue, or stop its processes (SIGTERM, then SIGKILL)."""
        if job.state in FINAL_STATES:
            return
        job.cancel_requested = True
        if job.state == "queued":
            with contextlib.suppress(ValueError):
                self.waiting.remove(job)
            self._finish(job, "cancelled")
            self._pump()
            return
        self._stop(job)

    def _stop(self, job: Job) -> None:
        process = job.process
        if process is None or process.returncode is not None:
            return
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(process.pid, signal.SIGTERM)
        loop = asyncio.get_running_loop()
        loop.call_later(KILL_GRACE, self._kill, process)

    @staticmethod
    def _kill(process: asyncio.subprocess.Process) -> None:
        if process.returncode is None:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(process.pid, signal.SIGKILL)

    async def shutdown(self) -> None:
        """Stop every job (the server is leaving) and wait for their processes."""
        for job in list(self.jobs.values()):
            self.cancel(job)
        for job in list(self.jobs.values()):
            if job.process is not None and job.process.returncode is None:
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(job.process.pid, signal.SIGKILL)
        if self.tasks:
            await asyncio.wait(self.tasks, timeout=5)

    def _pump(self) -> None:
        """Start waiting jobs while fewer than ``workers`` run; renumber the queue."""
        while self.waiting and len(self.running) < self.workers:
            job = self.waiting.popleft()
            self.running.add(job.id)
            job.state, job.position, job.started = "running", 0, time.monotonic()
            job.touch()
            task = asyncio.get_running_loop().create_task(self._run(job))
            self.tasks.add(task)
            task.add_done_callback(self.tasks.discard)
        for position, job in enumerate(self.waiting, start=1):
            if job.position != position:
                job.position = position
                job.touch()

    def _finish(self, job: Job, state: str, error: str | None = None) -> None:
        job.state, job.error, job.finished = state, error, time.monotonic()
        job.process = None
        job.touch()

    def _forget_old(self) -> None:
        """Remove the oldest finished jobs and their files beyond :data:`MAX_JOBS_KEPT`."""
        finished = [j for j in self.jobs.values() if j.state in FINAL_STATES]
        for job in finished[: max(0, len(self.jobs) - MAX_JOBS_KEPT + 1)]:
            for path in sorted(job.folder.glob("*")):
                path.unlink(missing_ok=True)
            with contextlib.suppress(OSError):
                job.folder.rmdir()
            del self.jobs[job.id]

    # ------------------------------------------------------------------ running
    async def _run(self, job: Job) -> None:
        deadline = time.monotonic() + self.timeout
        try:
            for index, argv in enumerate(job.plan.steps):
                job.step = index
                job.touch()
                code, last_error = await self._run_step(job, argv, deadline)
                if job.cancel_requested:
                    self._finish(job, "cancelled")
                    return
                problem = None
                if code is None:
                    problem = f"stopped after {self.timeout:g} s, the time limit of a job"
                elif code != 0:
                    problem = last_error or f"the job's process ended with status {code}"
                optional = job.plan.optional_from is not None and index >= job.plan.optional_from
                if problem is not None and optional:  # the output is there: keep it, say what is missing
                    job.warning = f"the output is ready, but measuring it failed: {problem}"
                    break
                if problem is not None:
                    self._finish(job, "failed", problem)
                    return
                self._collect(job)
            job.step = len(job.plan.steps)
            self._finish(job, "done")
        except Exception as exc:  # a bug of the server: the job fails, the server goes on
            self._finish(job, "failed", f"internal error: {type(exc).__name__}: {exc}")
        finally:
            self.running.discard(job.id)
            self._pump()

    async def _run_step(self, job: Job, argv: list[str], deadline: float) -> tuple[int | None, str | None]:
        """Run one process; ``(exit status or None on timeout, its last error line)``."""
        env = dict(os.environ)
        for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
            env[name] = str(self.threads)
        env["PYTHONUNBUFFERED"] = "1"
        env.pop("TEXSYN_DEBUG", None)
        process = await asyncio.create_subprocess_exec(
            *argv,
            cwd=job.folder,
            env=env,
            stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.DEVNULL,
            stderr=asyncio.subprocess.PIPE,
            start_new_session=True,
            limit=1 << 20,  # longest stderr line read whole
        )
        job.process = process
        if job.cancel_requested:  # cancelled while the process started
            self._stop(job)
        last_error: list[str] = []
        reader = asyncio.get_running_loop().create_task(self._read(job, process, last_error))
        try:
            await asyncio.wait_for(process.wait(), max(0.1, deadline - time.monotonic()))
        except TimeoutError:
            self._stop(job)
            await process.wait()
            await reader
            return None, None
        await reader
        return process.returncode, (last_error[-1] if last_error else None)

    async def _read(self, job: Job, process: asyncio.subprocess.Process, last_error: list[str]) -> None:
        """Progress records and error lines from a step's stderr."""
        assert process.stderr is not None
        folder = str(job.folder)
        while True:
            try:
                line = await process.stderr.readline()
            except ValueError:  # a line longer than the limit: skip it
                continue
            if not line:
                return
            text = line.decode("utf-8", "replace").strip()
            if text.startswith('{"progress"'):
                with contextlib.suppress(ValueError, TypeError, KeyError):
                    job.progress = json.loads(text)["progress"]
                    job.touch()
            elif text.startswith("texsyn: error:") or text.startswith("texsyn: internal error:"):
                message = text.split(":", 1)[1].strip()
                message = message[len("error:") :].strip() if message.startswith("error:") else message
                message = message.replace(job.plan.exemplar.argument, job.plan.exemplar.name)
                last_error.append(message.replace(folder + os.sep, "").replace(folder, "."))

    def _collect(self, job: Job) -> None:
        """Read what the page shows of a finished job and write its run JSON."""
        if job.plan.mode == "compare":  # the report names the user's file, not the server's copy
            stored, name = job.plan.exemplar.argument, job.plan.exemplar.name
            page, data = job.folder / "report.html", job.folder / "report.json"
            if page.is_file():
                page.write_text(
                    page.read_text(encoding="utf-8").replace(stored, html.escape(name)), encoding="utf-8"
                )
            if data.is_file():
                record = json.loads(data.read_text(encoding="utf-8"))
                record.update(command_line=job.plan.command_line, exemplar_path=name)
                if record.get("exemplar_name") == stored:
                    record["exemplar_name"] = name
                data.write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
        metrics = job.folder / "metrics.json"
        if metrics.is_file():
            job.metrics = json.loads(metrics.read_text())
        sidecars = {"synth": "texture.png.json", "animate": "animation.webm.json"}
        sidecar = job.folder / sidecars.get(job.plan.mode, "")
        run = job.folder / "run.json"
        if job.plan.mode in sidecars and sidecar.is_file() and not run.exists():
            record = json.loads(sidecar.read_text())
            record["command_line"] = job.plan.command_line
            record["inputs"] = {"exemplar": job.plan.exemplar.name}
            record["outputs"] = {
                key: item.download_name for key, item in job.plan.files.items() if key != "run"
            }
            run.write_text(json.dumps(record, indent=2) + "\n")
