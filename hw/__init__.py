"""hw: capture real tactile imprints from a sensor on a serial port.

Modules: :mod:`hw.protocol` (frame encoding and incremental parsing),
:mod:`hw.press` (baseline and press detection), :mod:`hw.session` (SQLite
capture sessions and their export to ``tactile.ImprintSet``),
:mod:`hw.session_file` (the session's SQLite file: schema, migration, transactions),
:mod:`hw.capture` (the capture loop, ``python -m hw.capture``),
:mod:`hw.simdevice` (a simulated sensor on a pty, ``python -m hw.simdevice``)
and :mod:`hw.plan` (probe plans for a robot).  Submodules are imported on
demand so that the command line stays fast.
"""
