"""The frequency side: FRF and modal data against the linearised model, and its candidates."""
