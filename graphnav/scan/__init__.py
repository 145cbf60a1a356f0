"""Scan matching: LiDAR scans to points (:mod:`.lidar`), weighted ICP and its covariance
(:mod:`.weighted_icp`, compiled loops in :mod:`._icp_fast`), degeneracy (:mod:`.degeneracy`), initial
guesses (:mod:`.motion_guess`), consecutive pairs of a log (:mod:`.icp_pairs`), the shared match
cache (:mod:`.icp_cache`), library registration (small_gicp/open3d, :mod:`.registration`) and
movement parameters from increments (:mod:`.movement`)."""
