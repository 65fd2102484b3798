// Job files and tool specs: values and errors with their places.
#include "cutsim/core/error.h"
#include "cutsim/io/job.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

TEST(Job, ReadsEverySection) {
  TempDir dir;
  const auto p = dir.write("j.toml",
                           "[stock]\nbox = [-1, -2, -3, 4, 5, 0]\n[tool]\nspec = \"flat:d=6\"\n"
                           "[simulation]\nvoxel_mm = 0.005\nstart = [0, 0, 12.5]\nmemory_limit_mb = 512\n");
  const io::Job j = io::load_job(p);
  ASSERT_TRUE(j.stock_box);
  EXPECT_DOUBLE_EQ(j.stock_box->min.y(), -2);
  EXPECT_DOUBLE_EQ(j.stock_box->max.x(), 4);
  ASSERT_TRUE(j.tool);
  EXPECT_EQ(j.tool->kind, tool::ToolKind::flat);
  EXPECT_DOUBLE_EQ(j.tool->diameter_mm, 6);
  EXPECT_DOUBLE_EQ(*j.voxel_mm, 0.005);
  EXPECT_DOUBLE_EQ(j.start_mm->z(), 12.5);
  EXPECT_DOUBLE_EQ(*j.memory_limit_mb, 512);
}

TEST(Job, UnknownKeyIsAConfigErrorAtItsLine) {
  TempDir dir;
  const auto p = dir.write("j.toml", "[stock]\nbox = [0,0,0,1,1,1]\n\n[simulation]\nvoxl_mm = 1\n");
  try {
    io::load_job(p);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.where().line, 5);
    EXPECT_EQ(e.where().column, 1);
    EXPECT_EQ(e.code(), ExitCode::config);
  }
}

TEST(Job, UnknownToolKindIsAConfigErrorAtTheSpec) {
  TempDir dir;
  const auto p = dir.write("j.toml", "[tool]\nspec = \"cone:d=1\"\n");
  try {
    io::load_job(p);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.where().line, 2);
    EXPECT_NE(e.message().find("unknown tool kind 'cone'"), std::string::npos);
  }
}

// [bench]: the goals `cutsim bench` prints a case's figures against; each
// optional, each a positive number, nothing else in the table.
TEST(Job, BenchGoalsAreReadAndCheckedAtTheirPlace) {
  TempDir dir;
  {
    const io::Job j = io::load_job(dir.write("g.toml", "[bench]\nmax_wall_s = 10\nmin_moves_per_s = 1e5\n"));
    ASSERT_TRUE(j.bench);
    EXPECT_DOUBLE_EQ(*j.bench->max_wall_s, 10);
    EXPECT_FALSE(j.bench->max_rss_mb);
    EXPECT_DOUBLE_EQ(*j.bench->min_moves_per_s, 1e5);
    EXPECT_FALSE(io::load_job(dir.write("none.toml", "[stock]\nbox = [0,0,0,1,1,1]\n")).bench);
  }
  auto fails_at = [&](const std::string& text, int line, int column, const std::string& what) {
    try {
      io::load_job(dir.write("bad.toml", text));
      ADD_FAILURE() << "accepted: " << text;
    } catch (const ConfigError& e) {
      EXPECT_EQ(e.where().line, line) << text;
      EXPECT_EQ(e.where().column, column) << text;
      EXPECT_NE(e.message().find(what), std::string::npos) << e.message();
      EXPECT_EQ(e.code(), ExitCode::config);
    }
  };
  fails_at("[bench]\nmax_wall_s = 10\nmax_rss_mb = 0\n", 3, 14, "max_rss_mb must be positive");
  fails_at("[bench]\nmin_moves_per_s = -5\n", 2, 19, "min_moves_per_s must be positive");
  fails_at("[bench]\nmax_wall_s = \"ten\"\n", 2, 14, "max_wall_s must be a finite number");
  fails_at("[bench]\nmax_wall = 10\n", 2, 1, "max_wall");
  fails_at("bench = 3\n", 1, 9, "[bench] must be a table");
}

TEST(Job, TomlSyntaxErrorHasLineAndColumn) {
  TempDir dir;
  const auto p = dir.write("j.toml", "[stock]\nbox = [0,0,0,1,1,\n");
  try {
    io::load_job(p);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_GE(e.where().line, 2);
    EXPECT_GT(e.where().column, 0);
  }
}

TEST(ToolSpec, ParsesKindsAndRejectsNonsense) {
  const auto b = tool::parse_tool_spec("bull:d=2,r=0.2,l=5");
  EXPECT_EQ(b.kind, tool::ToolKind::bull);
  EXPECT_DOUBLE_EQ(b.corner_radius_mm, 0.2);
  EXPECT_DOUBLE_EQ(b.flute_length_mm, 5);
  const auto env = tool::cutting_envelope(b);
  EXPECT_DOUBLE_EQ(env.disk_radius, 0.8);
  EXPECT_THROW(tool::parse_tool_spec("ball"), ConfigError);
  EXPECT_THROW(tool::parse_tool_spec("ball:d=-1"), ConfigError);
  EXPECT_THROW(tool::parse_tool_spec("ball:d=1,q=2"), ConfigError);
  EXPECT_THROW(tool::parse_tool_spec("flat:d=1,r=0.1"), ConfigError);
  EXPECT_THROW(tool::parse_tool_spec("bull:d=1,r=0.6"), ConfigError);
}

}  // namespace
}  // namespace cutsim::test
