"""The ``serve`` command: the local web page (``docs/web.md``)."""

from __future__ import annotations

import os

import click

from ..errors import InputError

__all__ = ["serve"]

#: seconds the server waits for open requests when it stops (event streams end at once)
GRACEFUL_SHUTDOWN = 3


@click.command()
@click.option(
    "--host", default="127.0.0.1", show_default=True, help="Address to listen on (loopback by default)."
)
@click.option(
    "--port", type=click.IntRange(1, 65535), default=8000, show_default=True, help="Port to listen on."
)
@click.option("--open", "open_browser", is_flag=True, help="Open the page in the default web browser.")
@click.option(
    "--workers",
    type=click.IntRange(1, 256),
    default=os.cpu_count() or 1,
    show_default="one per core",
    help="Jobs that run at once; the others wait in a queue.",
)
@click.option(
    "--queue",
    "queue_limit",
    type=click.IntRange(0, 10000),
    default=16,
    show_default=True,
    help="Jobs that may wait.",
)
@click.option(
    "--max-upload-mb",
    type=click.FloatRange(0.01, 10000),
    default=20.0,
    show_default=True,
    help="Largest upload in MB.",
)
@click.option(
    "--max-pixels",
    type=click.IntRange(1, 10**10),
    default=16_000_000,
    show_default=True,
    help="Largest exemplar in pixels (checked before decoding).",
)
@click.option(
    "--max-side",
    type=click.IntRange(8, 100_000),
    default=4096,
    show_default=True,
    help="Largest output side.",
)
@click.option(
    "--job-timeout",
    type=click.FloatRange(1, 86400),
    default=600.0,
    show_default=True,
    help="Seconds a job may run.",
)
@click.option(
    "--allow-host",
    "extra_hosts",
    multiple=True,
    metavar="NAME",
    help="Another name the page may be reached under (repeatable), e.g. this machine's name on the network.",
)
def serve(
    host,
    port,
    open_browser,
    workers,
    queue_limit,
    max_upload_mb,
    max_pixels,
    max_side,
    job_timeout,
    extra_hosts,
):
    """Serve a local web page to try every method on your own image.

    Prints the page's address, which carries a token that every request needs (so that other
    web pages you visit cannot use the server). Results live in a temporary folder removed
    when the server stops (Ctrl-C).
    """
    try:
        import uvicorn

        from ..web import ServerSettings, create_app, is_loopback
    except ImportError as exc:
        raise InputError(
            f"texsyn serve needs the web extra ({exc.name} is missing): pip install 'texsyn[web]'"
        ) from None
    settings = ServerSettings(
        host=host,
        port=port,
        workers=workers,
        queue_limit=queue_limit,
        max_upload_bytes=int(max_upload_mb * 1e6),
        max_pixels=max_pixels,
        max_side=max_side,
        job_timeout=job_timeout,
        extra_hosts=tuple(extra_hosts),
    )
    if not is_loopback(host):
        click.echo(
            f"texsyn: warning: listening on {host}, not loopback: other machines can reach the "
            "server (the token still guards it; anyone who sees the address can use it)",
            err=True,
        )
    click.echo(f"texsyn: serving on {settings.url}", err=True)
    click.echo("texsyn: Ctrl-C stops the server and removes its results", err=True)
    application = create_app(settings)

    class Server(uvicorn.Server):
        async def shutdown(self, sockets=None):
            # uvicorn waits for open requests before the application's shutdown, which stops
            # the jobs: an event stream of a page watching a job would hold it until the job
            # ends, so the streams end first (and any other request gets a moment only)
            application.end_streams()
            await super().shutdown(sockets)

    config = uvicorn.Config(
        application,
        host=host,
        port=port,
        log_level="warning",
        lifespan="on",
        timeout_graceful_shutdown=GRACEFUL_SHUTDOWN,
    )
    server = Server(config)
    if open_browser:
        import threading
        import webbrowser

        threading.Timer(1.0, webbrowser.open, args=(settings.url,)).start()
    server.run()
