"""Charging strategy plugins (entry-point group ``dispatch.chargers``): which idle electric
vehicles go charging, where, and to what state of charge. The contract is
:class:`dispatch.api.charger.ChargingStrategy`; parameters come from ``[charging.<name>]``.

* ``threshold`` (:mod:`chargers.threshold`): below ``low`` go to the station of least drive +
  queue time and charge to ``high``;
* ``idle`` (:mod:`chargers.idle`): charge opportunistically when idle within ``radius`` seconds
  of a station with a free plug (and below ``high``); plus ``threshold``'s rule below ``low``;
* ``valley`` (:mod:`chargers.valley`): charge to ``high`` while the demand of the last hour is
  below ``valley`` times the mean hourly demand so far (the day's valleys), only below ``low``
  otherwise.
"""
