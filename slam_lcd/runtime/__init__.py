"""How the process runs: interrupts and signals, thread limits, quiet third-party output, progress bars, lazy names, stage timers, the machine line."""
