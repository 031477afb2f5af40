"""Rest-pose stature of a BVH file counts its End Sites (closed form on a two-bone chain)."""

from __future__ import annotations

from gttdata.mocap.bvh import load_bvh

BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 90 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Neck
  {
    OFFSET 0 50 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 25 0
    }
  }
  JOINT Leg
  {
    OFFSET 0 -80 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 5 -10 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.01
0 90 0 0 0 0 0 0 0 0 0 0
0 90 0 0 0 0 0 0 0 0 0 0
"""


def test_rest_stature_includes_end_sites(tmp_path):
    path = tmp_path / "chain.bvh"
    path.write_text(BVH)
    motion = load_bvh(path, scale=0.01)
    # Highest point: head End Site at 50 + 25 above the hips; lowest: leg End Site 80 + 10 below them.
    assert abs(motion.provenance["rest_stature_m"] - (75 + 90) * 0.01) < 1e-12
    # The joints alone span only 50 + 80 units.
    z = motion.positions[0, :, 2]
    assert abs((z.max() - z.min()) - 1.30) < 1e-12
