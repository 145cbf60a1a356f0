"""The smoother's options in sections (issue #26 item 2): every flat name is an alias of one
``section.field``, generated from the sections; the forms a user can write give one config."""

from __future__ import annotations

import re
from dataclasses import fields

import pytest

from graphnav.config import given_option, option_names, sections
from graphnav.graph.smoother_config import GnssConfig, SmootherConfig

# the flat names of the options before the sections (main 5104ce7), each with the path it must reach
FLAT = {
    "lag": "optimizer.lag", "relinearize_threshold": "optimizer.relinearize_threshold",
    "isam_extra_updates": "optimizer.isam_extra_updates", "lm_tol": "optimizer.lm_tol",
    "keyframe_period": "keyframe.period", "scan_stride": "keyframe.scan_stride",
    "keyframe_angle_deg": "keyframe.angle_deg", "grid_gap": "keyframe.grid_gap",
    "compensate_attachment": "keyframe.compensate_attachment", "anchor_wait": "anchor.wait",
    "anchor_sigma_yaw_unknown_deg": "anchor.sigma_yaw_unknown_deg", "use_odometry": "odometry.use",
    "odo_sigma_w_deg": "odometry.sigma_w_deg", "odo_lateral": "odometry.lateral", "motion_model": "dynamics.model",
    "cv_sigma_v": "dynamics.cv_sigma_v", "motion_floor_yaw_deg": "dynamics.floor_yaw_deg",
    "v0_sigma": "dynamics.v0_sigma", "level_sigma_deg": "dynamics.level_sigma_deg", "icp_gate": "scan.icp_gate",
    "icp": "scan.icp", "loop": "scan.loop", "loops": "scan.loops", "cloud": "scan.cloud", "use_cloud": "scan.use_cloud",
    "gnss_gate": "gnss.gate", "gnss_gate_online": "gnss.gate_online", "gnss_velocity_sigma": "gnss.velocity_sigma",
    "attitude_sigma_deg": "compass.attitude_sigma_deg", "compass_bias": "compass.bias",
    "unknown_beacons": "beacon.unknown", "beacon_sigma_range_rel": "beacon.sigma_range_rel",
    "water_speed_sigma": "water.speed_sigma", "current_rw": "water.current_rw", "robust_groups": "robust.groups",
    "noise_estimation": "robust.noise_estimation", "noise_iterations": "robust.noise_iterations",
    "odometry_scale": "robust.odometry_scale",
    "solver": "solver", "motion": "motion", "imu": "imu", "mounts": "mounts",
}


def test_flat_names_are_aliases_of_one_path_each():
    table = option_names(SmootherConfig)
    for flat, path in FLAT.items():
        assert table[flat] == path, flat
    paths = {p for p in table.values()}
    flats = [n for n in table if "." not in n]
    assert len(flats) == len(paths) == 113  # one flat name per option, none lost, none shared
    assert table["deskew"] == "scan.deskew"  # added after the sections
    assert table["coast_max_s"] == "optimizer.coast_max_s"  # ... and with the coasting's time limit
    for name, sec in sections(SmootherConfig).items():  # every section field has its path
        assert all(table[f"{name}.{f.name}"] == f"{name}.{f.name}" for f in fields(sec))


def test_every_spelling_gives_the_same_config():
    want = SmootherConfig(gnss=GnssConfig(gate=3.0))
    assert want.gnss.gate == 3.0 and want.value("gnss_gate") == 3.0 and want.value("gnss.gate") == 3.0
    for kw in ({"gnss_gate": 3.0}, {"gnss.gate": 3.0}, {"gnss": {"gate": 3.0}}):
        assert SmootherConfig(**kw) == want, kw
        assert SmootherConfig.from_options(kw) == want, kw
    assert SmootherConfig() != want
    # a section object, then a field of it: the field wins; the last spelling of one option wins
    assert SmootherConfig(gnss=GnssConfig(gate=3.0, k=2.0), gnss_gate=5.0).gnss == GnssConfig(gate=5.0, k=2.0)
    assert SmootherConfig(**{"gnss_gate": 1.0, "gnss.gate": 2.0}).gnss.gate == 2.0
    assert SmootherConfig(keyframe_period=1.0).flat()["keyframe_period"] == 1.0


def test_given_option_reads_any_spelling_and_ignores_other_keys():
    for kw in ({"use_cloud": False}, {"scan.use_cloud": False}, {"scan": {"use_cloud": False}}):
        assert given_option(SmootherConfig, {**kw, "history": True}, "scan.use_cloud", True) is False
    assert given_option(SmootherConfig, {"scan": {"icp_gate": 2}}, "scan.use_cloud", True) is True


def test_unknown_names_fail_with_did_you_mean():
    for kw, close in (({"gnss_gat": 4}, "gnss_gate"), ({"gnss.gat": 4}, "gnss.gate"),
                      ({"gnss": {"gat": 4}}, "gnss.gate"), ({"keyframe_perod": 1}, "keyframe_period")):
        with pytest.raises(ValueError, match=rf"unknown smoother option.*did you mean '{re.escape(close)}'"):
            SmootherConfig(**kw)
    with pytest.raises(ValueError, match="unknown smoother option"):
        SmootherConfig(gnss={"gate": 4, "nope": 1})


def test_section_checks_name_the_flat_option():
    for kw, name in (({"keyframe_distance": 0}, "keyframe_distance"), ({"motion_model": "x"}, "motion_model"),
                     ({"batch_init_growth": 1.0}, "batch_init_growth"), ({"robust.prob": 1.0}, "robust_prob")):
        with pytest.raises(ValueError, match=name):
            SmootherConfig(**kw)


def test_a_flat_attribute_names_its_section():
    with pytest.raises(AttributeError, match=r"read \.gnss\.gate"):
        SmootherConfig().gnss_gate  # noqa: B018
    with pytest.raises(AttributeError, match="'nope'$"):
        SmootherConfig().nope  # noqa: B018


@pytest.mark.parametrize("options, message", [
    ({"water_scale_sigma": 0}, "water.scale_sigma must be > 0 or None, got 0"),
    ({"water_scale_rw": float("nan")}, "water.scale_rw must be > 0, got nan"),
    ({"water_scale_segment_s": -60.0}, "water.scale_segment_s must be > 0 or None"),
    ({"compass_bias_drift_deg": -1}, "compass.bias_drift_deg must be > 0, got -1"),
])
def test_a_scale_or_drift_that_is_not_positive_is_refused_by_name(options, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        SmootherConfig.from_options(options)
    off = SmootherConfig.from_options({"water_scale_sigma": None, "water_scale_segment_s": None})
    assert off.water.scale_sigma is None and off.water.scale_segment_s is None
