"""The built-in scenes: small tabletops of a few objects, centred at the origin, up = +z.

Each mixes diffuse, glossy (plastic, metal) and textured (checkerboard) materials, concave
objects and occluders, so that some views reveal what others cannot: a ball at the bottom of a
bowl or a cup is visible only from high viewpoints, an object hidden behind a wall or a box
only from one side. The third, `fence`, adds thin structures (rods a few hundredths of the
scene wide) in front of other objects.
"""

from mfsample.scenes.scene import Material, Scene, Shape

# The table top of every scene: a round plate whose top face is at z = TABLE.
TABLE = -0.3
_PLATE_THICKNESS = 0.04


def _plate(material, radius=0.85):
  return Shape("plate", "plate", material, position=(0.0, 0.0, TABLE - _PLATE_THICKNESS),
               params=(("radius", radius), ("thickness", _PLATE_THICKNESS)))


def tabletop():
  """The default scene: a bowl hiding a ball, a box behind a gold sphere, a torus, a can."""
  z = TABLE
  shapes = (
      _plate(Material("diffuse", (0.6, 0.55, 0.45), checker=(0.38, 0.32, 0.26), tiles=10.0)),
      Shape("bowl", "bowl", Material("plastic", (0.15, 0.3, 0.75), roughness=0.12),
            position=(-0.36, 0.26, z),
            params=(("radius", 0.32), ("height", 0.24), ("thickness", 0.03))),
      # Resting at the bottom of the bowl: seen only from above the rim.
      Shape("ball_in_bowl", "sphere", Material("diffuse", (0.85, 0.12, 0.1)),
            position=(-0.36, 0.26, z + 0.03 + 0.075), scale=(0.075, 0.075, 0.075)),
      Shape("box", "cube",
            Material("diffuse", (0.9, 0.85, 0.75), checker=(0.75, 0.2, 0.1), tiles=4.0),
            position=(0.42, 0.45, z + 0.15), scale=(0.15, 0.15, 0.15),
            rotation=(0.0, 0.0, 1.0, 25.0)),
      # In front of the box (seen from -y, -x): occludes it from some azimuths.
      Shape("gold_sphere", "sphere",
            Material("conductor", (1.0, 1.0, 1.0), roughness=0.2, metal="Au"),
            position=(0.22, 0.08, z + 0.17), scale=(0.17, 0.17, 0.17)),
      Shape("torus", "torus", Material("plastic", (0.2, 0.65, 0.25), roughness=0.3),
            position=(-0.34, -0.38, z),
            params=(("major", 0.19), ("minor", 0.06))),
      Shape("can", "can",
            Material("plastic", (0.9, 0.9, 0.85), roughness=0.25, checker=(0.1, 0.2, 0.65),
                     tiles=8.0),
            position=(0.34, -0.4, z), params=(("radius", 0.12), ("height", 0.4))),
  )
  return Scene("tabletop", shapes,
               description="bowl hiding a ball, checkered box behind a gold sphere, torus, "
                           "checkered can, on a checkered plate")


def still_life():
  """A second scene: a cup holding a cube, a wall hiding a ball, a copper vase, a stack."""
  z = TABLE
  shapes = (
      _plate(Material("plastic", (0.6, 0.6, 0.65), roughness=0.35)),
      Shape("cup", "cup", Material("plastic", (0.85, 0.85, 0.8), roughness=0.08),
            position=(-0.34, 0.34, z),
            params=(("radius", 0.17), ("height", 0.32), ("thickness", 0.02))),
      # Inside the cup: visible only from high viewpoints.
      Shape("cube_in_cup", "cube", Material("diffuse", (0.1, 0.75, 0.2)),
            position=(-0.34, 0.34, z + 0.02 + 0.065), scale=(0.065, 0.065, 0.065),
            rotation=(0.0, 0.0, 1.0, 30.0)),
      # A wall along the back with a ball behind it: seen only from +y.
      Shape("wall", "cube",
            Material("diffuse", (0.85, 0.8, 0.7), checker=(0.55, 0.35, 0.3), tiles=6.0),
            position=(0.25, 0.4, z + 0.18), scale=(0.36, 0.035, 0.18)),
      Shape("ball_behind_wall", "sphere", Material("plastic", (0.55, 0.1, 0.65), roughness=0.1),
            position=(0.25, 0.6, z + 0.1), scale=(0.1, 0.1, 0.1)),
      Shape("vase", "vase", Material("conductor", roughness=0.15, metal="Cu"),
            position=(-0.3, -0.34, z),
            params=(("radius", 0.15), ("height", 0.44))),
      Shape("lower_cube", "cube",
            Material("diffuse", (0.9, 0.85, 0.2), checker=(0.15, 0.15, 0.15), tiles=4.0),
            position=(0.4, -0.3, z + 0.13), scale=(0.13, 0.13, 0.13),
            rotation=(0.0, 0.0, 1.0, -15.0)),
      Shape("upper_cube", "cube", Material("diffuse", (0.2, 0.45, 0.9)),
            position=(0.39, -0.29, z + 0.26 + 0.085), scale=(0.085, 0.085, 0.085),
            rotation=(0.0, 0.0, 1.0, 20.0)),
      Shape("ring", "torus", Material("plastic", (0.95, 0.45, 0.1), roughness=0.2),
            position=(0.02, -0.05, z + 0.17), rotation=(1.0, 0.0, 0.0, 90.0),
            params=(("major", 0.13), ("minor", 0.04))),
  )
  return Scene("still_life", shapes,
               description="cup holding a cube, wall hiding a ball, copper vase, stacked "
                           "cubes, standing ring, on a glossy plate")


def _rod(name, material, base, length, radius, tilt=(1.0, 0.0, 0.0, 0.0)):
  """A thin closed cylinder standing on `base` along +z, then tilted (axis, degrees)."""
  return Shape(name, "can", material, position=base, rotation=tilt,
               params=(("radius", radius), ("height", length)))


def fence():
  """A third scene of thin structures and occlusion: a fence of thin rods in front of a ball
  and a box, a straw in a cup, a thin standing ring, two stakes in a V.

  The rods are 0.03-0.04 wide (about one pixel at the uncertainty benchmark's 64 x 64
  forward-facing views): what a few views of a Gaussian field reconstruct worst, as in the
  light-field scenes (basket, torch) of the paper's Table 5.
  """
  z = TABLE
  dark = Material("plastic", (0.12, 0.1, 0.08), roughness=0.3)
  shapes = [
      _plate(Material("diffuse", (0.7, 0.68, 0.6), checker=(0.3, 0.42, 0.35), tiles=12.0)),
      # Behind the fence (seen from -y): each is cut into strips by the rods.
      Shape("ball_behind_fence", "sphere", Material("diffuse", (0.85, 0.2, 0.12)),
            position=(0.12, 0.18, z + 0.14), scale=(0.14, 0.14, 0.14)),
      Shape("box_behind_fence", "cube",
            Material("diffuse", (0.9, 0.88, 0.8), checker=(0.2, 0.3, 0.7), tiles=4.0),
            position=(-0.28, 0.3, z + 0.16), scale=(0.16, 0.16, 0.16),
            rotation=(0.0, 0.0, 1.0, 20.0)),
      Shape("cup", "cup", Material("plastic", (0.85, 0.85, 0.8), roughness=0.1),
            position=(0.45, 0.35, z),
            params=(("radius", 0.12), ("height", 0.22), ("thickness", 0.015))),
      # A straw leaning in the cup: thin, and half hidden by the cup's wall.
      _rod("straw", Material("plastic", (0.1, 0.6, 0.85), roughness=0.2),
           (0.45, 0.35, z + 0.015), 0.4, 0.012, tilt=(1.0, 0.0, 0.0, 18.0)),
      Shape("thin_ring", "torus", Material("conductor", roughness=0.2, metal="Cu"),
            position=(0.48, -0.42, z + 0.16), rotation=(1.0, 0.0, 0.0, 90.0),
            params=(("major", 0.16), ("minor", 0.016))),
  ]
  # The fence: seven thin pickets and a top rail, across the middle of the plate.
  for i, x in enumerate(0.12 * (i - 3) for i in range(7)):
    shapes.append(_rod(f"picket_{i}", dark, (x, -0.12, z), 0.42, 0.018))
  shapes.append(_rod("rail", dark, (-0.42, -0.12, z + 0.36), 0.84, 0.015,
                     tilt=(0.0, 1.0, 0.0, 90.0)))
  for i, angle in enumerate((-24.0, 24.0)):
    shapes.append(_rod(f"stake_{i}", Material("diffuse", (0.8, 0.7, 0.3)),
                       (-0.5, -0.45, z), 0.55, 0.016, tilt=(0.0, 1.0, 0.0, angle)))
  return Scene("fence", tuple(shapes),
               description="fence of thin rods before a ball and a box, straw in a cup, thin "
                           "standing ring, two stakes in a V, on a checkered plate")


# Name -> constructor. "default" is the scene the README's main job runs on.
_BUILDERS = {
    "tabletop": tabletop,
    "still_life": still_life,
    "fence": fence,
}
DEFAULT_SCENE = "tabletop"
SCENES = ("default",) + tuple(_BUILDERS)


def get_scene(name="default"):
  """The built-in scene `name` (one of `SCENES`; "default" is "tabletop")."""
  key = DEFAULT_SCENE if name == "default" else name
  if key not in _BUILDERS:
    raise ValueError(f"unknown scene {name!r}; built-in scenes: {', '.join(SCENES)}")
  return _BUILDERS[key]()
