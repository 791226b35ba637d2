"""Experiments built on the engine and the simulator: the paper's reproduction (`reproduce`)."""
