#pragma once
// Machine description: the chain of joints from the workpiece to the tool
// (the shape-generation function of seeds/003), with assembly errors per
// joint, setting errors of tool and workpiece, axis limits and laser scales.
#include <array>
#include <optional>
#include <string>
#include <vector>

#include "cutsim/core/geometry.h"

namespace cutsim::machine {

/// Assembly error of a joint (seeds/003 eq. 2): translations in mm,
/// small rotations in radians about X (alpha), Y (beta), Z (gamma).
struct JointError {
  double dx = 0, dy = 0, dz = 0;
  double alpha = 0, beta = 0, gamma = 0;
  bool zero() const { return !dx && !dy && !dz && !alpha && !beta && !gamma; }
  /// The exact rigid transform: translation, then Rz(gamma) Ry(beta) Rx(alpha);
  /// to first order it is I + epsilon of eq. 2.
  Pose transform() const;
};

/// A laser-interferometer scale: its length reads with the air's refractive
/// index (seeds/000 eqs. 4-5).
struct LaserScale {
  double dead_path_mm = 0;   ///< L0: from zero path difference to the counter's origin
  double origin_mm = 0;      ///< axis position where the counter was reset
};

enum class JointType { linear, rotary };

struct Joint {
  char axis = 'X';               ///< program letter: X Y Z A B C
  JointType type = JointType::linear;
  Vec3 direction = Vec3::UnitX(); ///< unit
  Vec3 origin = Vec3::Zero();    ///< rotary: a point on the axis, mm
  double stroke_min = -1e9, stroke_max = 1e9;  ///< mm or rad
  double max_velocity = 0;       ///< mm/s or rad/s; 0: unchecked
  double max_acceleration = 0;   ///< mm/s^2 or rad/s^2; 0: unchecked
  JointError error;              ///< between this joint and the next towards the tool
  std::optional<LaserScale> laser;
};

struct Machine {
  std::string name;
  std::string description;
  std::string source;            ///< file or "preset"
  std::vector<Joint> chain;      ///< from the workpiece to the tool
  Pose tool_setting = Pose::Identity();       ///< setting error of the tool in its holder
  Pose workpiece_setting = Pose::Identity();  ///< setting error of the workpiece on the table
  double rapid_fraction = 1.0;   ///< rapids run at this fraction of each axis' max velocity

  /// Index of the joint driven by program letter `axis`, or -1.
  int joint_of(char axis) const;
  bool has_rotary() const;
};

/// A preset name (xyz, xyza, xyzbc, xzc, flycut) or a TOML file.
/// @throw ConfigError (file:line:col) for a bad file or an unknown preset;
///        InputError when the file cannot be read.
Machine load_machine(const std::string& name_or_file);

/// Names of the compiled-in presets.
std::vector<std::string> preset_names();

}  // namespace cutsim::machine
