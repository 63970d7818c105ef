"""Analysis of Parquet results: reading, metrics, tables, plots, reports, animations.

Reads Parquet only and imports neither torch nor PyBullet (nor the ``dispatch`` package), so a
results folder can be analysed on any machine with pyarrow, pandas and matplotlib:

* :mod:`analysis.io` - :func:`~analysis.io.open_results` on run / sweep folders;
* :mod:`analysis.metrics` - Tables I and III per allocator and N, taxi-style metrics;
* :mod:`analysis.timeline` - what each vehicle did when, from the events table;
* :mod:`analysis.plots` - the figures (matplotlib, Agg canvas, no pyplot);
* :mod:`analysis.report` - ``dispatch report``: Markdown / HTML with tables and figures;
* :mod:`analysis.render` - ``dispatch render``: an animated GIF from PyBullet camera images
  (imports PyBullet when called).

Importing any of these modules imports nothing heavy (matplotlib, PyBullet and Pillow are
imported inside the functions that use them).
"""
