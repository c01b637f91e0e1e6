"""A capture's report: one HTML page of what every stage made.

:mod:`~pipeline.report.sections` reads each stage's folder into the data its section shows (through a
:class:`~pipeline.report.reader.Reader`, which embeds pictures and notes missing files), :mod:`~pipeline.report.page`
lays it out with the Jinja2 templates in ``templates/``, :mod:`~pipeline.report.curves` draws the training curves.
The ``orca report`` stage (:mod:`pipeline.stages.report`) writes the page.
"""
