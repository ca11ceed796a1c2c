"""Dynamic identification of the hexapod (``docs/identification.md``).

- :mod:`.parameters`: the standard parameters (the model's, made linear) and their
  conversion to and from :class:`~hexapod.dynamics.InertiaParameters` and
  :class:`~hexapod.dynamics.DriveParameters`;
- :mod:`.regressor`: the inverse dynamic identification model ``f = Y(q, qd, qdd) theta``,
  derived from the expressions of :mod:`hexapod.dynamics.compiled`;
- :mod:`.base`: the base parameters (numerical QR of a stacked random regressor);
- :mod:`.excitation`: the Fourier excitation trajectory, optimised for the condition
  number;
- :mod:`.estimation`: weighted least squares, standard errors, physical consistency.
"""
