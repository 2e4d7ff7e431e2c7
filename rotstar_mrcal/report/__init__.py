"""The report of rotstar-report: pages, figures and mrcal's own views of a calibration

Modules, one concept each:

    page       the headline table, verdicts and detail tables as Markdown
               and HTML
    stereo     the stereo section (a pair against the truth, in depth terms)
    folder     the report folder: pages, figures copied and drawn, results
    plots      the figures (matplotlib, no display needed)
    mrcalshow  mrcal's mrcal-show-* views, with scales for our small errors
"""
