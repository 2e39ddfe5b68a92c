"""How a dance is drawn: the sampling controls, declared once (``table``), resolved into a draw
(``controls``), and chosen for a run on its dancer's takes (``calibrate``, saved in ``calibration_file``)."""
