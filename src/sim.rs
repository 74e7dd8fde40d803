//! The robot and its world: shapes, kinematic chains (host and tensor), the built-in robots and
//! URDF/STL loading, the camera, the ray caster that renders silhouettes and depth, the
//! joint-space trajectories a dataset is recorded along, changes to an arm (damage), and
//! collision spheres and checks for IK.

pub mod arm4;
pub mod arm_change;
pub mod bvh;
pub mod camera;
pub mod collision;
pub mod dh_robot;
pub mod kinematics;
pub mod mesh_file;
pub mod primitive_fit;
pub mod ray_caster;
pub mod robot;
pub mod robots;
pub mod shape;
pub mod srdf;
pub mod tensor_kinematics;
pub mod trajectory;
pub mod urdf_loader;
