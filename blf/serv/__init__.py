"""BLFserv, backlash in service (paper 2.2): from motor angle and LVDT only, no force.

Offers, by module:

* :mod:`~blf.serv.blfserv`: :func:`blf_serv` (batch) and :class:`BlfServMonitor` (streaming, the
  real-time form), ``METHODS`` (``"improved"``, ``"paper"``);
* :mod:`~blf.serv.results`: :class:`BlfServResult` per D channel, :class:`ServJump` per traversal;
* :mod:`~blf.serv.filters`: the low-pass and DT1 filters (python-control), :func:`design_serv_filters`,
  :class:`ServFilters`, the noise level :func:`estimate_noise_std_mm`, :func:`robust_noise_std`;
* :mod:`~blf.serv.scale`: the counted jumps held to the LVDT's unknown scale (:func:`with_known_scale`, the
  ram's travel through each :func:`motion_through_jumps`);
* :mod:`~blf.serv.detect`: the jump detector's compiled kernels (numba; internal).

Uses only blf's five modules.
"""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(__name__, submod_attrs={
    "blfserv": ["METHODS", "BlfServMonitor", "blf_serv"],
    "results": ["ServJump", "BlfServResult", "improved_reading", "paper_reading"],
    "scale": ["motion_through_jumps", "with_known_scale"],
    "filters": ["ServFilters", "design_serv_filters", "estimate_noise_std_mm", "robust_noise_std"],
})
