"""Repositioner plugins (entry-point group ``dispatch.repositioners``): what idle vehicles do
between trips. The contract is :class:`dispatch.api.repositioner.Repositioner`.

* ``stay`` (:mod:`repositioners.stay`): idle vehicles wait where they are (the default);
* ``demand`` (:mod:`repositioners.demand`): idle vehicles drive toward grid zones whose recent
  demand exceeds their idle supply.
"""
