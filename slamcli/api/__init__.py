"""File-level workflows that wire simulator → solver → io → metrics. The CLI and the sweep runner call these;
they never call each other. One module per workflow: ``simulate``, ``solve``, ``evaluate``."""
