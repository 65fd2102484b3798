#pragma once
#include "cutsim/cases/cases.h"

namespace cutsim::cases {

std::vector<File> snowflake_files();
std::vector<File> blade_files();
std::vector<File> lens_files();
std::vector<File> flycut_files();
std::vector<File> fouraxis_files();
std::vector<File> raster_files();

}  // namespace cutsim::cases
