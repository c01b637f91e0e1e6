"""Automatic object masks from a calibrated orbit, without learned weights (the masks stage's method).

Three cues, each cheap and each weak alone, made to agree:

1. **Where the cameras converge.** After ``poses`` the object lies inside the unit sphere of the normalized
   frame. Pixels whose ray misses the sphere are background, in every view, for certain.
2. **The support plane explains the floor.** The object stands on a table or floor. Under the plane's
   homography a floor pixel -- shadows included, they do not move with the viewpoint -- has the same colour in
   the neighbouring views, while an object pixel lands on unrelated content (it is not on the plane) and a
   glossy one changes with the viewpoint anyway. The plane is found by sweeping its height (normal: the
   cameras' mean up, then a small tilt search) for the most consistent pixels; photo-consistency with it marks
   floor pixels as background. Without this the contact shadow, dark like many glossy objects, is segmented
   as object in every view, and the visual hull grows a skirt down to the floor that no view from above can
   carve away.
3. **Colour, per view (GrabCut).** OpenCV's GrabCut (colour GMMs + contrast-sensitive graph cut) inside the
   projected sphere, seeded by what is known: cues 1 and 2 as certain background, the current visual hull's
   reprojection as probable object, its eroded core as object.

A fourth, where the poses stage triangulated points (:mod:`.tracks`): in each photo that observed a point, one on
the floor or far outside the sphere is certain background and one clearly above the floor inside the sphere
certain object.

They are made to agree by **visual-hull carving**: a voxel of the unit sphere is cut when ``carve_share`` of
the views (at least ``carve_votes``) see it off the object: a few, not one, so that a view that misses a piece
does not cut it out of every other view; not many, because next to a thin part only the few views looking
along it can see the gap. A background vote counts fully where evidence confirms it (outside the sphere, the
floor, the depth sweep) or where the pixel is not dark; a dark pixel's vote that nothing confirms counts
``doubtful_vote`` (0.5): the dark bottom of a glossy object on its dark contact shadow is lost by colour in every
view from above, and only the few views that see it against a lit background say otherwise. A vote from a pixel
the depth sweep explains by a surface *behind* the sphere counts ``confirmed_vote`` (3): its ray passes the
object empty, so a gap between the object's parts that few views see the room through is still carved. The hull,
reprojected into every view, seeds the next round of GrabCut; a few rounds settle. The hull knows nothing of
occlusion: where a prop stands between a camera and the object it covers the prop, and its core would force the
prop into that view's mask. So, from the second round, planes parallel to the support plane are swept between
each camera and the hull (:func:`front_evidence`): textured pixels -- texture in two directions, an edge
alone matches at any depth -- that such a plane explains in the neighbours, in blobs, whose column down to the
floor stays out of the hull (a prop stands beside the object; a chance match on the object's own texture has
the object under it), are a prop's top in front of the object, and the image of those columns in front of the
hull is its side: certain background, and the core is not forced next to them. And where fewer than
``carve_share`` of the views see through the object -- a hole, the space under a lifted side -- the hull fills
it; those views' pixels inside the hull's image that the support plane explains in *any* other view (one
suffices: the views that see through are few and on every side), textured in two directions, in blobs, are the
floor seen through the hull (:func:`floor_through_hull`): certain background, and the core is not forced within
``through_reach_px`` of them (they are textured specks of a larger hole; GrabCut decides the rest by colour).
The final mask of a view is
the last hull's reprojection within ``final_reach_px`` (1) of that view's last GrabCut mask, less certain
background: the hull keeps what one view's colours lose inside the object (a glossy rim mirroring the
background, a dark bottom), the view's own colours trim the hull's overhang at the outline (the hull is
larger than the object wherever fewer than ``carve_share`` of the views see past it) and cut the pieces of the
hull hidden by a prop in front (GrabCut gives them to the prop). Where that view's GrabCut mask disagrees with the
hull (it left out more than ``final_max_core_lost``, 15 %, of the hull's eroded core) its colours failed -- a
shadowed side lost to a dark floor -- and its final mask is the hull's reprojection less certain background.
Masks wrong alike in every view agree with their hull; a part lost that way (a mirror-like neck, paint coloured
like the room) leaves pixels beside every mask that no background surface explains. Where they amount to more
than ``unexplained_retry_share`` of a mask's area in the median view, the rounds run again with those pixels'
background votes not counted (:func:`.segment.refine_checked`).

Failure cases (documented in the README): an object not standing on a visible textured plane (hanging,
held, on a textureless table: cue 2 finds nothing and the contact shadow may stay in the masks); an
object whose colours are those of its surroundings *and* which is seen against them everywhere; fewer than
~8 views around the object (the hull then barely constrains anything); a loose unit sphere from ``poses``
that includes large props (they are carved only where views disagree; the sweep in front of the hull finds
props that stand on the floor with a textured top: not a prop hanging over the object, nor a round one's side
beyond its top's outline); holes through the object and the space under an overhang that fewer than
``carve_share`` of the views see through, where what shows through is not a textured floor (the hull fills
them, and inside the hull colour alone does not separate a glossy object from what it mirrors); thin parts
below the voxel size.

Modules: :mod:`.views` (views, the sphere prior, the knobs), :mod:`.support_plane`, :mod:`.hull`, :mod:`.grabcut`,
:mod:`.sweeps` (what is not the object), :mod:`.tracks` (the sparse points), :mod:`.segment` (the driver),
:mod:`.scale` (working size <-> full size).

Arrays: images ``(H, W, 3)`` uint8 sRGB at the working size; masks ``(H, W)`` bool; cameras OpenCV
camera-to-world ``(4, 4)`` and pinhole ``K`` ``(3, 3)`` at the working size (pixel (0, 0) is the image
corner, so scaling an image by ``s`` scales every entry of ``K``'s first two rows by ``s``).
"""
