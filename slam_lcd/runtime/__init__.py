"""How the process runs.

Interrupts and signals, thread limits, quiet third-party output, progress bars, lazy names,
stage timers, the machine line.
"""
