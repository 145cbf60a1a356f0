"""``graphnav register SOURCE TARGET --method M``: register two 3D point clouds (PLY, PCD, KITTI .bin)
and print T (4x4, source -> target frame), the time, the fitness and residual, and the covariance;
with ``--reference T.txt`` also the translation and rotation error against it."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..errors import GraphnavError
from ._common import add_json_flag, emit, plain_options


def _init(text: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--init {text!r}: expected six numbers x,y,z,roll,pitch,yaw") from None
    if len(vals) != 6 or not all(np.isfinite(vals)):
        raise argparse.ArgumentTypeError(f"--init {text!r}: expected six finite numbers x,y,z,roll,pitch,yaw")
    return vals


def register(sub: argparse._SubParsersAction) -> None:
    from ..scan.register3d import METHODS

    p = sub.add_parser("register", help="register two 3D point clouds (small_gicp, open3d, NDT)",
                       description=__doc__)
    p.add_argument("source", type=Path, help="source cloud: .ply, .pcd or KITTI .bin (float32 x,y,z,intensity)")
    p.add_argument("target", type=Path, help="target cloud (same formats)")
    p.add_argument("--method", choices=METHODS, default="gicp",
                   help="icp, p2plane, gicp, vgicp: small_gicp; ndt: Magnusson's 3D NDT (ours); "
                        "o3d-*: open3d (default gicp)")
    p.add_argument("--init", type=_init, metavar="x,y,z,roll,pitch,yaw",
                   help="initial T: metres and degrees, R = Rz(yaw) Ry(pitch) Rx(roll) (default identity)")
    p.add_argument("--voxel", type=float, metavar="M", help="downsampling voxel [m] (default 0.25; 0 = none)")
    p.add_argument("--reference", type=Path, metavar="T.txt",
                   help="reference T (4x4 or 3x4 text): print the translation [m] and rotation [deg] error")
    p.add_argument("--option", "-O", action="append", metavar="KEY=VALUE",
                   help="Reg3Params field, e.g. -O resolution=1.5 -O max_corr=2; repeatable")
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..io.cloudfile import read_cloud, read_transform
    from ..scan.register3d import pose_error, xyzrpy_matrix
    from ..scan.register3d import register as register_clouds

    params = plain_options(args)
    if args.voxel is not None:
        if not args.voxel >= 0:
            raise ValueError(f"--voxel must be >= 0, got {args.voxel}")
        params["voxel"] = args.voxel
    ref = read_transform(args.reference) if args.reference else None
    src, tgt = read_cloud(args.source), read_cloud(args.target)
    init = None
    if args.init is not None:
        x, y, z, r, pch, yaw = args.init
        init = xyzrpy_matrix(x, y, z, *np.radians([r, pch, yaw]))
    try:
        res = register_clouds(src, tgt, args.method, init, **params)
    except GraphnavError as err:  # "source"/"target": name the file
        files = {"source": str(args.source), "target": str(args.target)}
        if err.where in files:
            raise GraphnavError(f"{err.where} cloud: {err.message}", where=files[err.where]) from None
        raise
    out = {"source": str(args.source), "target": str(args.target), **res.as_dict()}
    out.pop("extra")
    out.update({k: v for k, v in res.extra.items() if k != "hessian"})
    out["options"] = params
    if ref is not None:
        dt, dr = pose_error(res.T, ref)
        out["reference"] = str(args.reference)
        out["translation_error_m"] = dt
        out["rotation_error_deg"] = dr
    T = np.asarray(res.T)
    sd = np.sqrt(np.clip(np.diag(res.cov), 0, None))
    lines = [f"method      {res.method}", "T (source -> target)"]
    lines += ["  " + " ".join(f"{v:11.6f}" for v in row) for row in T]
    lines += [f"ms          {res.ms:.1f} (prep {res.extra['ms_prep']:.1f}, align {res.extra['ms_align']:.1f})",
              f"fitness     {res.fitness:.4f}   rmse {res.rmse:.4f} m   objective {res.objective:.6g}",
              f"converged   {res.converged}   iterations {res.iterations}"
              + (f"   ({res.extra['reason']})" if res.extra.get("reason") else ""),
              "sigma       " + " ".join(f"{v:.3g}" for v in sd) + "   (omega [rad], v [m]; T exp(delta))"]
    if ref is not None:
        lines.append(f"error       {out['translation_error_m']:.4f} m   {out['rotation_error_deg']:.4f} deg")
    emit(args, out, "\n".join(lines))
    return 0
