"""The beacon-layout study: the fairway and its EKF-SLAM covariance search (:mod:`.layout`, compiled
kernel :mod:`._fast`) and the GTSAM cross-check (:mod:`.layout_graph`)."""
