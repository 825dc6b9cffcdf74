"""The ISET-LFM paper's figures reproduced with lfmbench (``lfmbench flicker-report``, ``lfmbench paper-figures``).

- :mod:`~lfmbench.paper.fig3`: Fig. 3, the temporal flicker of a PWM LED at 30 fps from the exact model (no render).
- :mod:`~lfmbench.paper.scenes`: how the two scene files of Figs. 4-7 (``lfmbench/configs/paper_figures/``) were
  made with the scene generator of ``render_tools`` (a maintainer tool; the files are the data of record).
- :mod:`~lfmbench.paper.figures`: Figs. 4-7 from a rendered corpus through the dataset and the baselines.

This package sits above the pipeline (it uses the renderer, the datasets and the baselines), beside the command
layer :mod:`lfmbench.cli`; no pipeline stage imports it. Details: docs/guide/paper-figures.md.
"""
