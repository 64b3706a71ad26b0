"""Simulators: the surface mass-spring model (MSM) and the phantom twin that writes lab sessions."""
