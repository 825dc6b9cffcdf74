"""``make demo``: the end-to-end job (``python -m lfmbench.demo``); steps in :mod:`lfmbench.pipeline_demo`."""
from __future__ import annotations

from lfmbench.flicker_report import FIG3_EXPOSURES_S, fig3_series


def main() -> None:
    s = fig3_series(frames=12)
    print("Flicker model (paper Fig. 3 settings: 95 Hz, D = 0.2, 30 fps):")
    for te in FIG3_EXPOSURES_S:
        print(f"  te = {te * 1e3:5.2f} ms  Phi[n] (ms ON) = {' '.join(f'{v * 1e3:.3f}' for v in s[te][:6])} ...  "
              f"FSI = {s[('fsi', te)]:.3f}")
    from lfmbench.pipeline_demo import run
    run()


if __name__ == "__main__":
    main()
