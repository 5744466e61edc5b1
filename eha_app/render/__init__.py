"""What the core computed, drawn for people: figures, tables, numbers, reports and exported files.

- :mod:`~eha_app.render.plots`, :mod:`~eha_app.render.board_plots`: Bokeh figures from result objects;
- :mod:`~eha_app.render.tables`, :mod:`~eha_app.render.formatting`, :mod:`~eha_app.render.glossary`:
  HTML of tables, numbers and transfer functions, and the words a student may hover;
- :mod:`~eha_app.render.layout`: how a tab's controls and results sit side by side;
- :mod:`~eha_app.render.report`: the reproduction report and the session report's frame;
- :mod:`~eha_app.render.exports`: CSV, JSON and zip files of results.

It draws; it neither computes physics nor knows about sessions or sections.
"""
