"""``make demo``: the end-to-end job. Each stage runs when its part of the package is present."""
from __future__ import annotations

import importlib.util
from pathlib import Path

from lfmbench.flicker_report import fig3_series, plot_fig3, FIG3_EXPOSURES_S

OUT = Path("demo_out")


def main() -> None:
    OUT.mkdir(exist_ok=True)
    s = fig3_series(frames=12)
    print("Flicker model (paper Fig. 3 settings: 95 Hz, D = 0.2, 30 fps):")
    for te in FIG3_EXPOSURES_S:
        print(f"  te = {te * 1e3:5.2f} ms  Phi[n] (ms ON) = {' '.join(f'{v * 1e3:.3f}' for v in s[te][:6])} ...  "
              f"FSI = {s[('fsi', te)]:.3f}")
    print(f"  plot: {plot_fig3(OUT / 'fig3_flicker.png')}")
    if importlib.util.find_spec("lfmbench.pipeline_demo"):
        from lfmbench.pipeline_demo import run
        run(OUT)


if __name__ == "__main__":
    main()
