"""Virtual IEEE P2020 flicker test bench (``lfmbench flicker-bench``): flicker KPIs of any sensor preset over PWM
frequency, duty, LED luminance and every phase, exactly; sequences at a frame rate; noise; real captures beside.
"""
