"""``hexapod-bench identify``: dynamic identification of a robot (``docs/identification.md``).

- :mod:`.record`: run an excitation on a backend that reports forces (the dynamic
  world, simulated in :mod:`.simulate`) and record encoder lengths and drive forces;
- :mod:`.command`: the command (excitation, record, estimation, outputs);
- :mod:`.outputs`: ``identified.toml``, ``identification.json``, the report and its plot;
- :mod:`.study`: the Monte Carlo coverage study and the closed loop.
"""
