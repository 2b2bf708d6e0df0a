// `octocd view` (design.md section 16, octocd/view.hpp) and `octocd validate --view`: the page's
// embedded data holds the engine's contact and the physics tier's reference for a planted
// fault, bad input exits 2 naming the argument, the page embeds only the trace's numbers,
// and a page of a 10^6-body trace viewed at a pair stays as small as one of 3 bodies.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "support/cli_run.hpp"
#include "support/external_trace.hpp"
#include "support/trace_edit.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_view {

namespace fs = std::filesystem;
using octocd::test::run_octocd;
using octocd::test::Trace;

namespace {

/// A fresh folder for one test.
std::string scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("octocd-test-view-" + std::to_string(::getpid()) + "-" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// The page's embedded data (<script type="application/json" id="octocd-data">).
nlohmann::json page_data(const std::string& page) {
  const std::string open = "<script type=\"application/json\" id=\"octocd-data\">";
  const std::size_t a = page.find(open);
  if (a == std::string::npos) return nullptr;
  const std::size_t b = page.find("</script>", a);
  return nlohmann::json::parse(page.substr(a + open.size(), b - a - open.size()));
}

/// The test trace (external_trace.hpp: boxes 1 and 2 overlap by 0.001 m along x, one
/// contact row per frame with the correct normal (-1, 0, 0), from body 2 to body 1) with
/// frame 2's normal flipped to (+1, 0, 0): a planted fault of the contact normal.
std::string flipped_trace(const std::string& dir) {
  Trace t;
  t.normal[3] = 1.0f;  // frame 2's row (offsets 1..2)
  const std::string path = dir + "/flipped.h5";
  t.write(path);
  return path;
}

const nlohmann::json* frame_of(const nlohmann::json& data, std::int64_t f) {
  for (const auto& fr : data["frames"])
    if (fr["frame"] == f) return &fr;
  return nullptr;
}

}  // namespace

TEST(CliView, PlantedFlippedNormalPageHoldsThePairAndBothNormals) {
  const std::string dir = scratch("flipped");
  const std::string trace = flipped_trace(dir);
  const auto r = run_octocd("view " + trace + " --frame 2 --pair 2,1 -o " + dir + "/out");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string page = slurp(dir + "/out/view-f2-pair-1-2.html");
  ASSERT_FALSE(page.empty()) << r.output;
  const nlohmann::json data = page_data(page);
  ASSERT_TRUE(data.is_object());
  EXPECT_EQ(data["item"]["kind"], "pair");
  EXPECT_EQ(data["item"]["a"], 1);
  EXPECT_EQ(data["item"]["b"], 2);
  EXPECT_EQ(data["frame"], 2);
  const nlohmann::json* f2 = frame_of(data, 2);
  ASSERT_NE(f2, nullptr);
  ASSERT_EQ((*f2)["contacts"].size(), 1u);
  const auto& c = (*f2)["contacts"][0];
  EXPECT_EQ(c["a"], 1);
  EXPECT_EQ(c["b"], 2);
  EXPECT_EQ(c["normal"], nlohmann::json::array({1, 0, 0}));  // the engine's (flipped)
  // The reference: two boxes overlapping by 0.001 m along x, minimum translation -x.
  ASSERT_FALSE(c["ref"].is_null());
  const auto& ref = (*f2)["references"][c["ref"].get<std::size_t>()];
  EXPECT_EQ(ref["a"], 1);
  EXPECT_EQ(ref["b"], 2);
  EXPECT_EQ(ref["judge"], "SAT");
  EXPECT_TRUE(ref["judged"]["penetrating"].get<bool>());
  EXPECT_NEAR(ref["judged"]["normal"][0].get<double>(), -1.0, 1e-6);
  EXPECT_NEAR(ref["judged"]["depth"].get<double>(), 0.001, 1e-5);
  EXPECT_NEAR(c["ref_normal"][0].get<double>(), -1.0, 1e-6);
  EXPECT_NEAR(c["angle_deg"].get<double>(), 180.0, 1e-3);
  // The frames around it keep the correct normal: the angle there is 0.
  const nlohmann::json* f1 = frame_of(data, 1);
  ASSERT_NE(f1, nullptr);
  ASSERT_EQ((*f1)["contacts"].size(), 1u);
  EXPECT_NEAR((*f1)["contacts"][0]["angle_deg"].get<double>(), 0.0, 1e-3);
  // The pair first (highlighted); body 0 lies 0.8 m away, beyond the pair's size: not drawn.
  ASSERT_EQ(data["bodies"].size(), 2u);
  EXPECT_TRUE(data["bodies"][0]["item"].get<bool>());
  EXPECT_EQ(data["bodies"][0]["id"], 1);
  // The page embeds the trace's numbers only: the root attribute engine ("test-engine")
  // is text of the file and never appears.
  EXPECT_EQ(page.find("test-engine"), std::string::npos);
  // three.js is inlined: no network.
  EXPECT_EQ(page.find("<script src"), std::string::npos);
  EXPECT_NE(page.find("OrbitControls"), std::string::npos);
  fs::remove_all(dir);
}

TEST(CliView, BadInputExitsTwoNamingTheArgument) {
  const std::string dir = scratch("bad");
  const std::string trace = flipped_trace(dir);
  const std::string out = " -o " + dir + "/out";
  struct Case {
    std::string args, names;
  };
  const std::vector<Case> cases = {
      {"--frame 4", "--frame: 4: outside the trace"},
      {"--frame 0", "--frame: 0"},
      {"--pair 1,3", "--pair: body 3 does not exist"},
      {"--pair 1,1", "--pair: 1,1: one body twice"},
      {"--pair x", "--pair: 'x'"},
      {"--body 9", "--body: body 9 does not exist"},
      {"--window 51", "--window: 51"},
      {"--pair 0,1 --body 2", "--pair and --body"},
  };
  for (const Case& c : cases) {
    const auto r = run_octocd("view " + trace + " " + c.args + out);
    EXPECT_EQ(r.code, 2) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.names), std::string::npos) << c.args << "\n" << r.output;
  }
  // A trace the hardened reader refuses: a non-finite position (named with the dataset).
  Trace t;
  t.position[4] = std::nanf("");
  t.write(dir + "/nan.h5");
  auto r = run_octocd("view " + dir + "/nan.h5 --frame 1" + out);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("/states/position"), std::string::npos) << r.output;
  // Not HDF5 at all.
  std::ofstream(dir + "/text.h5") << "not a trace";
  r = run_octocd("view " + dir + "/text.h5" + out);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("text.h5"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir + "/out/view-f1-all.html"));
  fs::remove_all(dir);
}

TEST(CliView, PairNotInContactIsDrawnWithANote) {
  const std::string dir = scratch("apart");
  const std::string trace = flipped_trace(dir);
  const auto r = run_octocd("view " + trace + " --frame 1 --pair 0,2 --window 0 -o " + dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("pair (0, 2) has no contact row in frame 1"), std::string::npos) << r.output;
  const nlohmann::json data = page_data(slurp(dir + "/view-f1-pair-0-2.html"));
  ASSERT_TRUE(data.is_object());
  EXPECT_NE(data["note"].get<std::string>().find("no contact row"), std::string::npos);
  ASSERT_EQ(data["frames"].size(), 1u);
  const auto& f = data["frames"][0];
  EXPECT_FALSE(f["pair_in_contact"].get<bool>());
  // The pair still has its reference: apart by 1 - 0.2 m along y, nearest points between.
  ASSERT_GE(f["references"].size(), 1u);
  const auto& ref = f["references"][0];
  EXPECT_EQ(ref["a"], 0);
  EXPECT_EQ(ref["b"], 2);
  EXPECT_FALSE(ref["judged"]["penetrating"].get<bool>());
  EXPECT_NEAR(ref["judged"]["distance"].get<double>(), 0.8, 1e-4);
  fs::remove_all(dir);
}

// 10^6 boxes on a grid (one frame, states only, no contacts): a page viewed at a pair
// holds the pair and at most the cap of bodies near it, whatever the trace's size. The
// trace is written uncompressed (76 MB) in well under a second.
TEST(CliView, MillionBodyTraceViewedAtAPairWritesABoundedPage) {
  const std::string dir = scratch("large");
  const std::string path = dir + "/grid.h5";
  const hsize_t n = 1000000, side = 100;  // 100^3 boxes of side 0.1 m, 0.15 m apart
  {
    std::vector<float> lo(3 * n, -0.05f), hi(3 * n, 0.05f), w(n, 1.0f), x(2 * 3 * n), v(2 * 3 * n, 0.0f);
    for (hsize_t r = 0; r < 2; ++r)
      for (hsize_t i = 0; i < n; ++i) {
        x[(r * n + i) * 3 + 0] = 0.15f * static_cast<float>(i % side);
        x[(r * n + i) * 3 + 1] = 0.15f * static_cast<float>((i / side) % side);
        x[(r * n + i) * 3 + 2] = 0.15f * static_cast<float>(i / (side * side));
      }
    octocd::test::write_minimal_trace(path, {{"/bodies/local_aabb_min", {n, 3}, &lo},
                                             {"/bodies/local_aabb_max", {n, 3}, &hi},
                                             {"/bodies/inverse_mass", {n}, &w},
                                             {"/states/position", {2, n, 3}, &x},
                                             {"/states/velocity", {2, n, 3}, &v}});
  }
  // Bodies 505050 and 505051 are grid neighbours in the middle of the block.
  const auto r = run_octocd("view " + path + " --frame 1 --pair 505050,505051 -o " + dir + "/out");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string page = slurp(dir + "/out/view-f1-pair-505050-505051.html");
  const nlohmann::json data = page_data(page);
  ASSERT_TRUE(data.is_object());
  EXPECT_EQ(data["bodies_in_trace"], n);
  EXPECT_LE(data["bodies"].size(), data["cap"].get<std::size_t>());
  EXPECT_EQ(data["bodies"][0]["id"], 505050);
  EXPECT_EQ(data["bodies"][1]["id"], 505051);
  // Bounded: three.js (about 0.9 MB) plus at most 64 bodies over 1 frame: under 1.5 MB.
  EXPECT_LT(page.size(), 1500000u) << page.size();
  fs::remove_all(dir);
}

// `validate --view DIR`: the failing example of the planted flipped normal gets its page,
// linked by a path relative to each file that names it (table: as given; JSON and JUnit:
// from their own folder), so the artifact folder works wherever it is unpacked.
TEST(CliView, ValidateViewLinksThePageFromTableJsonAndJunit) {
  const std::string dir = scratch("validate");
  const std::string trace = flipped_trace(dir);
  fs::create_directories(dir + "/art/junit");
  const auto r = run_octocd("validate --trace-in " + trace + " --view " + dir + "/art/pages --json " + dir +
                            "/art/result.json --junit " + dir + "/art/junit/report.xml");
  ASSERT_EQ(r.code, 3) << r.output;
  const std::string page = dir + "/art/pages/contact-geometry-normal-angle-f2-pair-1-2.html";
  EXPECT_NE(r.output.find("view: 1 page(s) of failing examples"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("contact-geometry/normal-angle frame 2 pair (1, 2): " + page), std::string::npos)
      << r.output;
  ASSERT_TRUE(fs::exists(page));
  const nlohmann::json data = page_data(slurp(page));
  ASSERT_TRUE(data.is_object());
  EXPECT_EQ(data["failure"]["row"], "contact-geometry");
  EXPECT_EQ(data["failure"]["cause"], "normal-angle");
  EXPECT_NEAR(data["failure"]["figure"].get<double>(), 180.0, 1e-3);
  // JSON: the example's "view", relative to the JSON's folder.
  const nlohmann::json doc = nlohmann::json::parse(slurp(dir + "/art/result.json"));
  std::string link;
  for (const auto& row : doc["rows"])
    if (row["name"] == "contact-geometry")
      for (const auto& c : row["causes"])
        for (const auto& x : c["examples"])
          if (x.contains("view")) link = x["view"].get<std::string>();
  EXPECT_EQ(link, "pages/contact-geometry-normal-angle-f2-pair-1-2.html");
  EXPECT_TRUE(fs::exists(dir + "/art/" + link));
  // JUnit: the failure message names the page, relative to the report's folder.
  const std::string junit = slurp(dir + "/art/junit/report.xml");
  EXPECT_NE(junit.find("view: ../pages/contact-geometry-normal-angle-f2-pair-1-2.html\""), std::string::npos)
      << junit;
  fs::remove_all(dir);
}

// A version 2 trace (rotation, a manifold with points, declared materials): the page
// holds the orientations as given, each manifold row with its point, and the reference of
// the pair judged on the posed (rotated) boxes.
TEST(CliView, VersionTwoTraceKeepsOrientationsAndManifoldPoints) {
  const std::string dir = scratch("v2");
  Trace t = Trace::make_v2();
  // Frame 1's rows with a second witness point 1 mm inside B, and friction vectors: the page
  // carries both per row (null for a trace without them).
  t.point_b = {0.099f, 0.05f, 0.05f, 0.099f, -0.05f, -0.05f, 0.099f, 0, 0, 0.099f, 0.05f, 0, 0.099f, -0.05f, 0};
  t.jt3 = {0, 0.001f, 0, 0, -0.002f, 0, 0, 0.003f, 0, 0, 0, 0, 0, 0.005f, 0};
  t.write(dir + "/v2.h5");
  const auto r = run_octocd("view " + dir + "/v2.h5 --frame 1 --pair 1,2 --window 0 -o " + dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const nlohmann::json data = page_data(slurp(dir + "/view-f1-pair-1-2.html"));
  ASSERT_TRUE(data.is_object());
  EXPECT_EQ(data["trace_version"], 2);
  const auto& f = data["frames"][0];
  // Body 1 (drawn first) is turned 0.3 rad about z: q = (cos 0.15, 0, 0, sin 0.15).
  EXPECT_NEAR(f["q"][0][0].get<double>(), std::cos(0.15), 1e-6);
  EXPECT_NEAR(f["q"][0][3].get<double>(), std::sin(0.15), 1e-6);
  // Frame 1's two-row manifold, each row with its world point (external_trace.hpp).
  ASSERT_EQ(f["contacts"].size(), 2u);
  EXPECT_NEAR(f["contacts"][0]["point"][1].get<double>(), 0.05, 1e-6);
  EXPECT_NEAR(f["contacts"][1]["point"][1].get<double>(), -0.05, 1e-6);
  EXPECT_NEAR(f["contacts"][0]["point_b"][0].get<double>(), 0.099, 1e-6);
  EXPECT_NEAR(f["contacts"][1]["point_b"][1].get<double>(), -0.05, 1e-6);
  EXPECT_NEAR(f["contacts"][1]["jt3"][1].get<double>(), -0.002, 1e-6);
  // Both rows share the pair's reference, computed on the posed boxes.
  EXPECT_EQ(f["contacts"][0]["ref"], f["contacts"][1]["ref"]);
  const auto& ref = f["references"][f["contacts"][0]["ref"].get<std::size_t>()];
  EXPECT_TRUE(ref["judged"]["valid"].get<bool>());
  // The pair's friction as the cone judges it: both rows together, mu sum jn against
  // |sum jt3| (or sum |jt|), their ratio.
  ASSERT_TRUE(ref.contains("friction")) << ref.dump();
  const auto& fr = ref["friction"];
  EXPECT_EQ(fr["rows"], 2);
  const double jn = f["contacts"][0]["jn"].get<double>() + f["contacts"][1]["jn"].get<double>();
  EXPECT_NEAR(fr["jn_sum"].get<double>(), jn, 1e-6 * std::max(1.0, jn));
  EXPECT_NEAR(fr["cone"].get<double>(), fr["mu"].get<double>() * jn, 1e-6 * std::max(1.0, jn));
  if (fr["rule"] == "scalar") {
    EXPECT_NEAR(fr["jt_sum"].get<double>(),
                std::fabs(f["contacts"][0]["jt"].get<double>()) + std::fabs(f["contacts"][1]["jt"].get<double>()), 1e-6);
  }
  if (jn > 0) {
    EXPECT_NEAR(fr["ratio"].get<double>(), fr["jt_sum"].get<double>() / fr["cone"].get<double>(), 1e-5);
  }
  fs::remove_all(dir);
}

namespace {

/// Rows [0, rows) of an integer or float dataset of `file`, as doubles (empty when absent).
std::vector<double> read_column(const std::string& file, const char* name) {
  std::vector<double> out;
  const hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (f < 0) return out;
  const hid_t d = H5Dopen2(f, name, H5P_DEFAULT);
  if (d >= 0) {
    const hid_t space = H5Dget_space(d);
    hsize_t dims[3] = {0, 1, 1};
    const int rank = H5Sget_simple_extent_dims(space, dims, nullptr);
    hsize_t count = 1;
    for (int k = 0; k < rank; ++k) count *= dims[k];
    out.resize(count);
    H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data());
    H5Sclose(space);
    H5Dclose(d);
  }
  H5Fclose(f);
  return out;
}

}  // namespace

// README's main job writes its trace with octocd run's defaults: a state every 10 frames
// and no contact rows. `octocd view` on it opens at the first frame the run counted a
// contact in; a frame without a state is drawn at the nearest recorded one, named; the
// slider steps over recorded states.
TEST(CliView, MainJobTraceWithSparseStatesOpens) {
  const std::string dir = scratch("sparse");
  const std::string trace = dir + "/bunny-stack-50.h5";
  const std::string scene = (fs::path(octocd::test::source_dir()) / "datasets" / "scenes" / "bunny-stack-50.json").string();
  auto r = run_octocd("run " + scene + " --frames 400 --trace " + trace);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<double> state_frames = read_column(trace, "/states/frame");
  ASSERT_GT(state_frames.size(), 2u);
  ASSERT_EQ(state_frames[1], 10.0) << "the main job's default --state-every";
  const std::vector<double> frame = read_column(trace, "/frames/frame"), contacts = read_column(trace, "/frames/contacts");
  ASSERT_EQ(frame.size(), contacts.size());
  std::int64_t first_contact = 0;
  for (std::size_t k = 0; k < frame.size() && first_contact == 0; ++k)
    if (contacts[k] > 0) first_contact = static_cast<std::int64_t>(frame[k]);
  ASSERT_GT(first_contact, 1) << "the bunnies fall before they touch";

  r = run_octocd("view " + trace + " -o " + dir + "/out");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string page = dir + "/out/view-f" + std::to_string(first_contact) + "-all.html";
  ASSERT_TRUE(fs::exists(page)) << r.output;
  const nlohmann::json data = page_data(slurp(page));
  ASSERT_TRUE(data.is_object());
  EXPECT_EQ(data["frame"], first_contact);
  EXPECT_NE(data["note"].get<std::string>().find("nearest recorded state"), std::string::npos);
  // No contact rows in the trace: the page says so plainly.
  EXPECT_EQ(data["has_contact_rows"], false);
  EXPECT_NE(data["note"].get<std::string>().find("this trace has no contact rows"), std::string::npos);
  EXPECT_NE(r.output.find("this trace has no contact rows"), std::string::npos) << r.output;
  // Recorded states and the frame asked for on the slider; each frame's state is the
  // recorded one nearest to it, and a recorded frame's positions are its /states row.
  const std::vector<double> position = read_column(trace, "/states/position");
  const std::size_t n = data["bodies_in_trace"].get<std::size_t>();
  bool asked = false;
  for (const auto& f : data["frames"]) {
    const std::int64_t fr = f["frame"], shown = f["state_frame"];
    asked = asked || fr == first_contact;
    EXPECT_EQ(shown % 10, 0) << fr;
    EXPECT_LE(std::llabs(shown - fr), 5) << fr;
    EXPECT_TRUE(fr == first_contact || fr == shown) << fr << ": only recorded states and the frame asked for";
    const std::size_t row = static_cast<std::size_t>(shown / 10);
    for (int k = 0; k < 3; ++k)  // body 0's x as drawn is its recorded state
      EXPECT_NEAR(f["x"][0][k].get<double>(), position[(row * n + 0) * 3 + k], 1e-5) << fr;
  }
  EXPECT_TRUE(asked);
  if (first_contact > 60) {
    EXPECT_EQ(data["frames"].size(), 11u) << "5 recorded states each side, and the frame";
  }

  // --frame 7 --window 2: frame 7 is drawn at frame 10's state, beside frames 10 and 20
  // (frame 0's state, before it, is the initial one, not a step).
  r = run_octocd("view " + trace + " --frame 7 --window 2 -o " + dir + "/out");
  ASSERT_EQ(r.code, 0) << r.output;
  const nlohmann::json seven = page_data(slurp(dir + "/out/view-f7-all.html"));
  ASSERT_TRUE(seven.is_object());
  std::vector<std::int64_t> slider, shown;
  for (const auto& f : seven["frames"]) {
    slider.push_back(f["frame"]);
    shown.push_back(f["state_frame"]);
  }
  EXPECT_EQ(slider, (std::vector<std::int64_t>{7, 10, 20}));
  EXPECT_EQ(shown, (std::vector<std::int64_t>{10, 10, 20}));
  fs::remove_all(dir);
}

}  // namespace octocd_test_cli_view
