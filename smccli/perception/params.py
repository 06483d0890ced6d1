"""Parameters of the object-cluster pipeline and of the cluster distance."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from smccli.world.scene import Scene


@dataclass(frozen=True, slots=True)
class PerceptionParams:
    """Knobs of :func:`~smccli.perception.clusters_from_frame` and :func:`d_cluster`.

    The crop box is per scene (it must hold the table top and what stands on it, and
    exclude the floor): a scene's trees start with the box its arm can reach
    (:func:`scene_perception`) unless the scene file sets one. The defaults here are the
    box of the first built-in scenes (the world origin at the robot's base on the table
    top, the table in front along +x), used only where no scene is known.
    """

    crop_min: tuple[float, float, float] = (0.15, -0.65, -0.05)
    """Lower corner of the workspace box, world frame [m]."""
    crop_max: tuple[float, float, float] = (1.0, 0.65, 0.6)
    """Upper corner of the workspace box, world frame [m]."""
    crop_touch: float = field(default=0.005, metadata={"omit_default": True})
    """A cluster with points this close to a face of the crop box may be cut by it: record,
    doctor and compile warn [m] (a pixel spans 2-3 mm at 0.6 m in 320x240)."""
    crop_frame: str = field(default="world", metadata={"omit_default": True})
    """Frame of the crop box: ``world``, or ``base`` for a mobile manipulator (the box moves
    with the robot: in front of it, at the height its hand works)."""
    remove_walls: bool = field(default=False, metadata={"omit_default": True})
    """Also remove the big planes of any orientation (door panels, cabinet sides) before
    clustering, so that a handle standing off a door is a cluster of its own (a mobile
    manipulator's scenes; a tabletop has only the table's plane)."""
    wall_min_points: int = field(default=400, metadata={"omit_default": True})
    """A plane with fewer inliers than this is not removed as a wall (a box's face)."""
    max_depth: float = 5.0
    """Depth readings beyond this are "nothing hit" (renderers return the far plane) [m]."""
    voxel_size: float = 0.0
    """Voxel size for downsampling before the plane fit and clustering; 0 = off [m]: not
    needed at 320x240."""
    plane_distance: float = 0.006
    """RANSAC inlier distance of the table plane [m]; also the margin above the table
    below which points count as table."""
    plane_iterations: int = 200
    """RANSAC iterations of the plane fit."""
    plane_sample: int = 4000
    """RANSAC runs on at most this many points (an even stride over the cloud); the plane
    is then refined by least squares on all its inliers."""
    plane_max_tilt: float = 0.25
    """The table plane's normal must be within this angle of world z [rad]."""
    plane_seed: int = 0
    """Seed of open3d's RANSAC, so that the same frame gives the same clusters."""
    outlier_neighbours: int = field(default=0, metadata={"omit_default": True})
    """Radius outlier removal once the table is gone (open3d ``remove_radius_outlier``): a
    point with fewer neighbours than this within ``outlier_radius`` is dropped; 0 = off.
    For a noisy depth camera (:mod:`smccli.world.noise`): table pixels whose noise lifts
    them above ``plane_distance`` stand alone and would join the object beside them (a 4 cm
    box measured 5 cm wide); measured on ideal frames, it changes no extent."""
    outlier_radius: float = field(default=0.008, metadata={"omit_default": True})
    """Radius of the outlier removal [m]."""
    dbscan_eps: float = 0.015
    """DBSCAN neighbourhood radius [m]; objects closer than this merge."""
    dbscan_min_points: int = 5
    """DBSCAN core-point neighbour count."""
    min_cluster_points: int = 30
    """Clusters with fewer points are noise and dropped."""
    hue_bins: int = 12
    """Hue bins of the chromatic part of the histogram."""
    sat_bins: int = 3
    """Saturation bins of the chromatic part of the histogram."""
    val_bins: int = 3
    """Brightness bins of the achromatic part of the histogram: dark / mid / bright. More
    bins split a white object's faces by their shading, which changes with the pose."""
    chroma_threshold: float = 0.15
    """Pixels whose chroma max(R,G,B) - min(R,G,B) (in [0, 1]) is below this are
    achromatic and binned by brightness only: their hue is noise."""
    hist_scale: float = 3.5
    """Textbook Bhattacharyya distance -ln BC that counts as "clearly different" (-> 1):
    BC = 0.03, no common colour. T_hP = 0.1 then sits at -ln BC = 0.35 (BC = 0.7)."""
    extent_scale: float = 2.5
    """Log-ratio of extents |ln(a/b)| that counts as "clearly different" (-> 1): T_hP = 0.1
    then sits at a 28 % size difference (with the colours equal)."""
    extent_tolerance: float = field(default=0.0, metadata={"omit_default": True})
    """What an extent measured from pixels is known to [m]: two extents closer than this are
    equal, farther ones compared on what is left
    (:func:`~smccli.perception.distance.d_cluster_matrix`). 0 = exact (the default). A
    box's width seen with a side face in view is its footprint's; seen with its sides out
    of sight, only the top face's pixel centres less the edge pixels a noisy camera drops
    (``bench_pick_lookalike``'s 4 cm box: 3.3-4.2 cm over 14 operators, stop 54): 0.004
    there."""
    brightness_ring: float = field(default=0.15, metadata={"omit_default": True})
    """The table within this of an object's centre is its brightness reference [m]
    (:mod:`smccli.perception.brightness`): the spot light falls off across the table."""
    brightness_gap: float = field(default=0.015, metadata={"omit_default": True})
    """Table points within this of the object's points are left out of its reference:
    edge pixels mix the two surfaces [m]."""
    brightness_scale: float = field(default=0.0, metadata={"omit_default": True})
    """Log-ratio of relative brightnesses |ln(a/b)| that counts as "clearly different"
    (-> 1); 0 = the term is off and not measured (the default). Turn it on (4) for a
    camera whose exposure varies among achromatic look-alikes under a lamp from above
    (``bench_pick_lookalike``: a white box against itself up to 0.36, against a grey bar
    of its size from 0.11). Under a light from one side a box's sides differ by up to 3
    times (the perception tests' lamp): there it would split one object in two
    (:mod:`smccli.perception.brightness`)."""
    top_band: float = 0.008
    """Points within this of the top form the top layer, whose centre is the footprint's
    centre [m]."""
    elongation_ratio: float = 1.2
    """Footprints with length / width above this are elongated (yaw period pi)."""
    round_fill: float = 0.88
    """Footprints filling less than this of their bounding rectangle are round
    (yaw period 0): a disc fills pi/4 = 0.79, a square 1."""
    protrusion_margin: float = 0.01
    """Points lying further than this outside the top layer's convex hull (in x-y) are a
    protrusion, such as a mug's handle [m]. The walls of boxes and cylinders are vertical:
    their points lie at most 6 mm outside it (measured; the scale's housing, 3.5 mm wider
    than its platform, 9 mm)."""
    protrusion_min_points: int = 5
    """Fewer points than this outside the margin are not a protrusion: they are left out
    of the footprint and the object is described as symmetric (a glimpse of a handle
    behind the body)."""
    protrusion_max_share: float = 0.35
    """A protrusion holds at most this share of the cluster's points, so that the top layer
    covers the body: a pyramid's top layer is its apex and 52-76 % of its points lie
    outside it; a mug's handle holds at most 16 % (measured)."""
    protrusion_max_spread: float = 0.2
    """The protrusion's points must lie on one side of the top's centre: circular standard
    deviation of their directions from it at most this [rad]. A mug's handle: 0.05-0.08;
    the rim of a cylinder under an off-centre cube: mostly 0.3-0.7 (measured)."""
    silhouette_step: float = 0.01
    """A cluster's pixel is cut when a neighbouring pixel outside the cluster is not at
    least this much farther from the camera [m]: there an occluder, the self-filter or the
    crop hides part of the object. A protrusion is looked for only when no pixel of the
    top layer is cut (a top partly hidden by the arm makes its sides stick out of it)."""
    hidden_min_points: int = field(default=10, metadata={"omit_default": True})
    """A cluster with this many points bordering something in front of it is partly
    hidden (:attr:`Cluster.hidden`): looking again, its centre is not the object's."""
    attach_gap: float = 0.035
    """A cluster hidden in part behind a taller one, touching it in the image and within
    this of it across the touching pixels, is a part of it [m]: a mug's handle behind its
    body is cut off by the body's occlusion shadow (measured: 1.5-3.0 cm across, in a third
    of the poses)."""
    attach_min_contacts: int = 3
    """Touching pixel pairs needed to attach a hidden part (see ``attach_gap``)."""
    attach_max_ratio: float = 0.5
    """A hidden part has at most this many times the points of the cluster hiding it: a
    mug's cut-off handle has at most 0.23 times its body's (measured over 300 poses), while
    a cylinder under a held cube, bigger than the cube, stays an object of its own."""
    join_overlap: float = field(default=0.25, metadata={"omit_default": True})
    """Two clusters standing on the same surface whose footprints (convex hulls in x-y,
    each grown by ``join_margin``) share this much of the smaller one's area are parts of
    one object (:func:`~smccli.perception.segment.join_split_parts`): two objects cannot
    stand on the same floor space, but a noisy camera's holes along an open box's 1 cm
    walls cut the box into its floor and its near walls (such parts share 0.46-1.0, a
    pyramid and its cut-off apex, which stay apart, at most 0.45; two objects 0)."""
    join_margin: float = field(default=0.0075, metadata={"omit_default": True})
    """How far each footprint grows before the overlap is measured [m]: half of
    ``dbscan_eps``, so parts closer than DBSCAN's reach overlap."""
    join_base: float = field(default=0.02, metadata={"omit_default": True})
    """Only clusters that reach down to within this of their surface stand on it and are
    joined [m]: an object held above another is not part of it."""
    piece_gap: float = field(default=0.05, metadata={"omit_default": True})
    """Two clusters on the same surface whose footprints come this near [m] may be pieces
    of one object (:func:`~smccli.perception.clusters.cluster_unions`): the floor of an
    open box split from its near wall by depth holes comes 2.5-27 mm near it."""


def scene_perception(scene: Scene) -> PerceptionParams:
    """The perception settings a scene's trees start with: the defaults with the scene
    file's ``perception`` section; an arm's crop box, unless the scene sets it, from its
    reach and its objects (:func:`~smccli.perception.reach.workspace_box`)."""
    settings: dict[str, Any] = dict(scene.perception)
    if scene.robot.base is None and scene.robot.arm_joints:
        from smccli.perception.reach import workspace_box

        lo, hi = workspace_box(scene)
        settings.setdefault("crop_min", lo)
        settings.setdefault("crop_max", hi)
    return replace(PerceptionParams(), **settings)
