// Free rotation judged by its invariants (docs/validation.md, "Free rotation: the
// invariants"): a torque-free asymmetric body precesses, its w changing while its angular
// momentum L = R I R^T w is kept. Bullet's runs of rot-spin-free (three boxes of unequal
// half extents keeping w, a bunny hull precessing) and of bunny-stack-50 (bunnies
// precessing in free flight between contacts) pass free-flight and momentum-balance with
// the gyroscopic handling undeclared; faults planted in a copy of each trace on a free,
// precessing body-step (w x1.5, one component of w + 0.1 rad/s, a 1 cm teleport, an
// edited linear velocity) exit 3 naming the frame and the body. The body-steps are found
// in the traces, never pinned by number.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <regex>
#include <string>
#include <vector>

#include "support/cli_run.hpp"
#include "support/trace_edit.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_free_rotation {

namespace fs = std::filesystem;

namespace {

using octocd::test::Data;
using octocd::test::read;
using octocd::test::Result;
using octocd::test::run_octocd;
using octocd::test::source_dir;
using octocd::test::write;

/// The verdict of the physics row `name` in a printed table: "pass", "FAIL" or "n/a".
std::string verdict(const Result& r, const std::string& name) {
  const std::regex line("(^|\n)physics +" + name + " +[^ ]+ +[^ ]+ +(pass|FAIL|n/a)");
  std::smatch m;
  return std::regex_search(r.output, m, line) ? m[2].str() : std::string("missing");
}

/// A Bullet trace with its states and contact rows, and a free body-step of it.
struct Trace {
  std::string path;
  int bodies = 0, frames = 0;
  Data x, v, w, inv_mass, offsets, pair;

  void load(const std::string& p) {
    path = p;
    const hid_t f = H5Fopen(p.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(f, 0) << p;
    x = read(f, "/states/position");
    v = read(f, "/states/velocity");
    w = read(f, "/states/angular_velocity");
    inv_mass = read(f, "/bodies/inverse_mass");
    offsets = read(f, "/contacts/offsets");
    pair = read(f, "/contacts/pair");
    H5Fclose(f);
    ASSERT_EQ(w.dims.size(), 3u);
    frames = static_cast<int>(w.dims[0]) - 1;
    bodies = static_cast<int>(w.dims[1]);
  }
  /// Body i has a contact row in step f (1-based).
  bool touches(int f, int i) const {
    for (auto r = static_cast<std::size_t>(offsets.v[std::size_t(f - 1)]); r < std::size_t(offsets.v[std::size_t(f)]);
         ++r)
      if (int(pair.v[2 * r]) == i || int(pair.v[2 * r + 1]) == i) return true;
    return false;
  }
  std::size_t at(int row, int i) const { return (static_cast<std::size_t>(row) * bodies + i) * 3; }
  /// |w after step f - w before it| of body i.
  double dw(int f, int i) const {
    double s = 0;
    for (int k = 0; k < 3; ++k) s += std::pow(w.v[at(f, i) + k] - w.v[at(f - 1, i) + k], 2);
    return std::sqrt(s);
  }
  /// The dynamic body and frame f (steps f and f + 1 free of contact rows) whose w
  /// changes most in step f: the most precessing free body-step.
  std::pair<int, int> precessing() const {
    int bf = -1, bi = -1;
    double best = 0;
    for (int f = 1; f < frames; ++f)
      for (int i = 0; i < bodies; ++i)
        if (inv_mass.v[std::size_t(i)] > 0 && !touches(f, i) && !touches(f + 1, i) && dw(f, i) > best) {
          best = dw(f, i);
          bf = f;
          bi = i;
        }
    return {bf, bi};
  }
};

class FreeRotation : public ::testing::Test {
 protected:
  static fs::path dir_;
  static Trace spin_, stack_;
  static bool have_data_;

  static void SetUpTestSuite() {
    have_data_ = std::ifstream(cache() + "/bunny.obj").good();
    if (!have_data_) return;
    dir_ = fs::temp_directory_path() / ("octocd-free-rotation-" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    if (!dir_.empty()) fs::remove_all(dir_, ec);
  }
  void SetUp() override {
    if (!have_data_) GTEST_SKIP() << "needs the fetched datasets (" << source_dir() << "/datasets/cache/bunny.obj)";
  }
  static std::string cache() { return source_dir() + "/datasets/cache"; }

  /// Bullet's run of `scene` over `frames` frames with every state and contact row, loaded
  /// into `t` (once a test program: each test records only the trace it reads).
  static void record(const std::string& scene, int frames, Trace& t) {
    if (!t.path.empty()) return;
    const std::string trace = (dir_ / (scene + ".h5")).string();
    const Result r = run_octocd("run " + source_dir() + "/datasets/scenes/" + scene + ".json --engine bullet " +
                                "--rotation --frames " + std::to_string(frames) + " --trace " + trace +
                                " --state-every 1 --contacts --no-xdmf --quiet --data-dir " + cache());
    ASSERT_EQ(r.code, 0) << r.output;
    t.load(trace);
  }
  /// rot-spin-free: three boxes and a bunny spinning apart, no contacts.
  static void record_spin() { record("rot-spin-free", 600, spin_); }
  /// bunny-stack-50: its first precessing free flights come after the first bounces
  /// (~frame 350).
  static void record_stack() { record("bunny-stack-50", 400, stack_); }

  /// `validate --trace-in` of `path`, the frame-sampled rows (the geometric rows and
  /// impulse-feasibility) every `every`-th step: the free rows (free-flight,
  /// momentum-balance, conservation, friction) judge every step either way.
  static Result judged(const std::string& path, int every) {
    return run_octocd("validate --trace-in " + path + " --every " + std::to_string(every) + " --data-dir " + cache());
  }

  /// A copy of `t` with `edit` applied to its states, judged (free-flight judges every
  /// step; the sampled rows every 100th, whose work on bunny-stack-50 is the most).
  Result planted(const Trace& t, const std::string& name, const std::function<void(hid_t)>& edit) {
    const fs::path p = dir_ / (name + ".h5");
    fs::copy_file(t.path, p, fs::copy_options::overwrite_existing);
    const hid_t f = H5Fopen(p.string().c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    EXPECT_GE(f, 0);
    edit(f);
    H5Fclose(f);
    return judged(p.string(), 100);
  }

  /// The four faults on body i after step f of `t`, each failing `free-flight` naming the
  /// frame and the body.
  void expect_faults_caught(const Trace& t, const std::string& tag, int f, int i) {
    const std::string who = "frame " + std::to_string(f) + ": body " + std::to_string(i) + " without contacts: ";
    struct Fault {
      const char* name;
      const char* dataset;
      std::function<void(Data&, std::size_t)> edit;
      std::string expect;
    };
    const std::vector<Fault> faults = {
        {"w15", "/states/angular_velocity",
         [](Data& d, std::size_t o) {
           for (int k = 0; k < 3; ++k) d.v[o + k] *= 1.5;
         },
         who + "w'"},
        {"wx01", "/states/angular_velocity", [](Data& d, std::size_t o) { d.v[o] += 0.1; }, who + "w'"},
        {"teleport", "/states/position", [](Data& d, std::size_t o) { d.v[o + 2] += 0.01; }, who + "x'"},
        {"velocity", "/states/velocity", [](Data& d, std::size_t o) { d.v[o] += 0.05; }, who + "v'"},
    };
    for (const Fault& fault : faults) {
      const Result r = planted(t, tag + "-" + fault.name, [&](hid_t h) {
        Data d = read(h, fault.dataset);
        fault.edit(d, t.at(f, i));
        write(h, fault.dataset, d);
      });
      EXPECT_EQ(r.code, 3) << fault.name << "\n" << r.output;
      EXPECT_EQ(verdict(r, "free-flight"), "FAIL") << fault.name << "\n" << r.output;
      EXPECT_NE(r.output.find(fault.expect), std::string::npos) << fault.name << ": no '" << fault.expect << "' in\n"
                                                                << r.output;
    }
  }
};

fs::path FreeRotation::dir_;
Trace FreeRotation::spin_, FreeRotation::stack_;
bool FreeRotation::have_data_ = false;

TEST_F(FreeRotation, BulletsSpinningBodiesPassEveryPhysicsRow) {
  ASSERT_NO_FATAL_FAILURE(record_spin());
  const Result spin_verdict = judged(spin_.path, 1);
  EXPECT_EQ(spin_verdict.code, 0) << spin_verdict.output;
  for (const char* row : {"broadphase-completeness", "contact-completeness", "contact-geometry", "penetration",
                          "friction", "conservation", "momentum-balance", "free-flight"})
    EXPECT_NE(verdict(spin_verdict, row), "FAIL") << row << "\n" << spin_verdict.output;
  EXPECT_EQ(verdict(spin_verdict, "free-flight"), "pass") << spin_verdict.output;
  // The bunny precesses (its w turns by more than 0.1 rad/s over the run) and passes by
  // the invariants; the boxes keep w.
  const auto [f, i] = spin_.precessing();
  ASSERT_GT(f, 0);
  EXPECT_GT(spin_.dw(f, i), 1e-4) << "no precessing body: the scene would not test the invariants";
  std::smatch m;
  ASSERT_TRUE(std::regex_search(spin_verdict.output, m, std::regex("(\\d+) kept w, (\\d+) precessed keeping L")))
      << spin_verdict.output;
  EXPECT_GT(std::stoi(m[1].str()), 0) << spin_verdict.output;
  EXPECT_GT(std::stoi(m[2].str()), 0) << spin_verdict.output;
}

TEST_F(FreeRotation, EditsOfASpinningBodyFailFreeFlight) {
  ASSERT_NO_FATAL_FAILURE(record_spin());
  const auto [f, i] = spin_.precessing();
  ASSERT_GT(f, 0);
  expect_faults_caught(spin_, "spin", f, i);
  // A box keeping w: its angular velocity x1.5 in the middle of the run.
  int box = -1;
  for (int b = 0; b < spin_.bodies && box < 0; ++b)
    if (spin_.inv_mass.v[std::size_t(b)] > 0 && b != i && spin_.dw(300, b) < 1e-4) box = b;
  ASSERT_GE(box, 0);
  const Result r = planted(spin_, "spin-box", [&](hid_t h) {
    Data d = read(h, "/states/angular_velocity");
    for (int k = 0; k < 3; ++k) d.v[spin_.at(300, box) + k] *= 1.5;
    write(h, "/states/angular_velocity", d);
  });
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("frame 300: body " + std::to_string(box) + " without contacts: w'"), std::string::npos)
      << r.output;
}

TEST_F(FreeRotation, BulletsBunnyStackPassesFreeFlightAndMomentumBalance) {
  ASSERT_NO_FATAL_FAILURE(record_stack());
  // Every row, the sampled ones (impulse-feasibility above all) on every 10th step.
  const Result stack_verdict = judged(stack_.path, 10);
  for (const char* row : {"free-flight", "momentum-balance"})
    EXPECT_EQ(verdict(stack_verdict, row), "pass") << row << "\n" << stack_verdict.output;
  EXPECT_EQ(stack_verdict.code, 0) << stack_verdict.output;
  const auto [f, i] = stack_.precessing();
  ASSERT_GT(f, 0);
  EXPECT_GT(stack_.dw(f, i), 1e-3) << "no bunny precessing in free flight within 400 frames";
}

// The precessing bunny's four faults, each in a copy of the one 400-frame trace.
TEST_F(FreeRotation, EditsOfAPrecessingBunnyFailFreeFlight) {
  ASSERT_NO_FATAL_FAILURE(record_stack());
  const auto [f, i] = stack_.precessing();
  ASSERT_GT(f, 0);
  expect_faults_caught(stack_, "stack", f, i);
}

}  // namespace

}  // namespace octocd_test_cli_free_rotation
