"""The response side: tip records through the simulation, and the candidates only a simulation shows."""
