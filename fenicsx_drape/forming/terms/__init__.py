"""The nodal terms of the forming residual besides the truss, each with its stiffness.

- :mod:`~fenicsx_drape.forming.terms.contact`: penalty contact with the rigid tools (and
  tool friction);
- :mod:`~fenicsx_drape.forming.terms.holder`: the blank holder: clamping and the friction
  bars of eq. 1;
- :mod:`~fenicsx_drape.forming.terms.stabilisation`: the out-of-plane spring of the slack net.
"""
