"""The built-in metric features, one class per module, registered in the ``fusionbench.features`` entry-point group:
:class:`~fusionbench.features.jump.JumpWindow` (``jump_window_s``: before / during / after a noise jump),
:class:`~fusionbench.features.windows.AttitudeWindows` (``rmse_window_s``, ``amplitude_windows_s``),
:class:`~fusionbench.features.compare.Comparison` (``compare``: seed 004's (Gu 2017, adaptive Schuler damping) eq. 14
reduction between two methods) and :class:`~fusionbench.features.paper.PaperClaims` (``[paper]``: the source paper's
claims beside ours). The protocol they follow and the registry are :mod:`fusionbench.bench.feature`."""
