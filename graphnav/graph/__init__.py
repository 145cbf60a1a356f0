"""Factor graphs: the record-by-record builder and its solvers (:mod:`.log_runs`: batch LM,
iSAM2, fixed-lag), its state spaces (:mod:`.space`) and IMU preintegration (:mod:`.imu_chain`), keyframes
(:mod:`.keyframes`) and the minimal online graph (:mod:`.graph_online`). Factors come from the
top-level :mod:`factors` package."""
