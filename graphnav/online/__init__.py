"""Online estimation: estimators by name and the record loop (:mod:`.runner`), the EKF record by
record (:mod:`graphnav.estimators.ekf_online`), live mode on sockets/serial (:mod:`.live_runner`) and log replay
(:mod:`.nmea_replay`)."""
