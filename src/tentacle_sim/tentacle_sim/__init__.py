"""Device emulators on pseudo-terminals and the simulated rig."""
