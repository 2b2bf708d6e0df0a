// `octocd run|validate --rotation` and rotating scenes on the command line (design.md section 13):
// cpu refuses them with exit 2 naming the key, `--rotation` needs `--engine bullet`, and
// Bullet with rotation writes a version 2 trace.
#include <gtest/gtest.h>
#include <hdf5.h>

#include <filesystem>
#include <string>

#include "support/cli_run.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_rotation {

using octocd::test::Result;
using octocd::test::run_octocd;
using octocd::test::source_dir;

namespace {

std::string scene(const std::string& name) { return source_dir() + "/datasets/scenes/" + name + ".json"; }

/// The integer root attribute `version` of an HDF5 file (-1 when unreadable).
int trace_version(const std::string& path) {
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (f < 0) return -1;
  int v = -1;
  const hid_t a = H5Aopen(f, "version", H5P_DEFAULT);
  if (a >= 0) {
    H5Aread(a, H5T_NATIVE_INT, &v);
    H5Aclose(a);
  }
  H5Fclose(f);
  return v;
}

}  // namespace

TEST(CliRotation, CpuRefusesARotatingSceneNamingTheKey) {
  const Result r = run_octocd("run " + scene("rot-slope") + " --quiet --frames 2");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("rot-slope.json: rotation: engine cpu translates only"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--engine bullet"), std::string::npos) << r.output;
  // validate without --engine runs a rotating scene on Bullet (test_cli_hostile_input); cpu asked for is refused.
  const Result v = run_octocd("validate " + scene("rot-stack-10") + " --engine cpu --frames 2");
  EXPECT_EQ(v.code, 2) << v.output;
  EXPECT_NE(v.output.find("rotation: engine cpu"), std::string::npos) << v.output;
}

TEST(CliRotation, RotationFlagNeedsBullet) {
  const Result r = run_octocd("run " + scene("box-stack") + " --rotation --quiet --frames 2");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--rotation: engine cpu translates only"), std::string::npos) << r.output;
  // Box mode records nothing (the default hull mode records and is validated).
  const Result v = run_octocd("validate " + scene("box-stack") + " --engine bullet --bullet shape=box --frames 2");
  EXPECT_EQ(v.code, 2) << v.output;
  EXPECT_NE(v.output.find("bullet with boxes equal to the AABBs and no rotation cannot be validated"),
            std::string::npos)
      << v.output;
}

TEST(CliRotation, BulletWritesVersion2AndTranslationOnlyVersion1) {
  namespace fs = std::filesystem;
  const std::string v2 = (fs::temp_directory_path() / "octocd-cli-rot-v2.h5").string();
  const std::string v1 = (fs::temp_directory_path() / "octocd-cli-rot-v1.h5").string();
  Result r = run_octocd("run " + scene("box-stack") + " --engine bullet --rotation --quiet --frames 20 --trace " + v2 +
                        " --state-every 1 --contacts --no-xdmf");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(trace_version(v2), 2);
  // Box mode: version 1 (hull mode, the default, writes version 2 without orientations).
  r = run_octocd("run " + scene("box-stack") + " --engine bullet --bullet shape=box --quiet --frames 20 --trace " +
                 v1 + " --state-every 1 --contacts --no-xdmf");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(trace_version(v1), 1);
  r = run_octocd("run " + scene("rot-slope") + " --engine bullet --quiet --frames 20");
  EXPECT_EQ(r.code, 0) << r.output;
  std::error_code ec;
  fs::remove(v1, ec);
  fs::remove(v2, ec);
}

}  // namespace octocd_test_cli_rotation
