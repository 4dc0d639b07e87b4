"""Pure geometry and kinematics that the scene builder, the controllers and the calibrations
all need: rotations, the Stewart platform's geometry/IK/FK, the Panda's nominal MD-H table and
limits, MD-H (+beta) chains and product-of-exponentials kinematics. numpy only, no MuJoCo."""

if not __name__.startswith("serpar."):  # a repository folder is a serpar subpackage, not a top-level name
    raise ModuleNotFoundError(f"No module named {__name__!r}; import serpar.{__name__}", name=__name__)
