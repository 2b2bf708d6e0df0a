#pragma once
/// \file view.hpp
/// A viewer of a frame (design.md section 16; `octocd view`, `octocd validate --view`, Python
/// `octocd.view`): one self-contained HTML page that draws the posed shapes of the bodies
/// near an item (a pair or a body) of a trace, their world AABBs, the engine's contact
/// points and normals (arrows scaled by depth, each pair its own scale), the reference's
/// normal and points (the separating-axis test or FCL, computed by the physics tier's own
/// code: validation/physics/reference.hpp), each pair's friction as the friction row's cone
/// judges it (sum jn n, the cone mu sum jn, the friction impulse and their ratio; pair_friction
/// in octocd/physics.hpp), with a frame slider over a window around the frame. The text panel
/// lies beside the scene; a trace without contact rows says so (docs/debugging.md).
///
/// Input: an octocd trace (version 1) or an external trace (versions 1 and 2), read only
/// through the hardened external-trace reader (octocd/external.hpp ExternalTrace) with
/// TraceStates::Sparse: a trace that records the state of some frames only (`octocd run`'s
/// default `--state-every 10`) draws a frame without its own state at the nearest recorded
/// one, and the page names it beside the frame number. The page embeds the trace's
/// numbers only (positions, orientations, boxes, meshes of the shapes, contacts, the
/// reference's figures) as JSON in a `<script type="application/json">` block, and three.js
/// (Debian's libjs-three: three.min.js, OrbitControls.js, ConvexHull.js, ConvexGeometry.js)
/// inlined: it opens from a file, with no network and no server.
///
/// Size: at most ViewSettings::max_bodies bodies near an item (max_bodies_all without one),
/// at most 2 x window + 1 frames (sparse states: the frame asked for and `window` recorded
/// states each side), at most kMaxContactRows rows and kMaxReferencePairs
/// references a frame: a page of a 10^6-body trace viewed at a pair is as large as one of
/// 10 bodies (three.js, about 0.9 MB, plus the shapes of the bodies drawn). The trace is
/// read in O(bodies) per frame of the window.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>

namespace octocd {

/// What a page shows and where its parts come from.
struct ViewSettings {
  /// The frame shown first (1 .. the trace's frames; 0: the first frame with a contact,
  /// ExternalTrace::first_contact_frame, else frame 1). InputError "--frame" outside the
  /// trace.
  std::int64_t frame = 0;
  /// The item: a pair (pair_a, pair_b; either order, two different bodies) or a body;
  /// neither: every body up to max_bodies_all. InputError "--pair" / "--body" for a body
  /// that does not exist.
  bool has_pair = false;
  std::uint32_t pair_a = 0, pair_b = 0;
  bool has_body = false;
  std::uint32_t body = 0;
  /// Frames each side of `frame` on the slider (0 .. kMaxWindow); with sparse states,
  /// recorded states each side.
  int window = 5;
  /// Most bodies drawn around an item: the item's, then the nearest others whose world
  /// AABB lies within the item's size of the item's box (>= 2).
  std::size_t max_bodies = 64;
  /// Most bodies drawn without an item (the first bodies by index; the page says so).
  std::size_t max_bodies_all = 500;
  /// `--mesh-dir`: where the meshes named by the trace's scene may lie (ExternalOptions::
  /// mesh_dir; "" = the trace's folder).
  std::string mesh_dir;
  /// Debian's libjs-three folder (three.min.js; examples/js/...).
  std::string three_dir = "/usr/share/javascript/three";
  /// The file written in the output folder; "": view-fF-pair-A-B.html, view-fF-body-I.html
  /// or view-fF-all.html.
  std::string file_name;
  /// Optional failure this page shows (validate --view): octocd's row and cause names and
  /// the figure in its unit (never text taken from the trace).
  std::string row, cause, unit;
  double figure = 0;
  /// Polled before every frame of the window is read and every pair reference computed;
  /// when it returns true write_view throws ValidationStopped and writes nothing. May be
  /// empty (never stops). `octocd.view` polls Ctrl-C (KeyboardInterrupt).
  std::function<bool()> stop;
};

/// Largest ViewSettings::window.
constexpr int kMaxWindow = 50;
/// Most engine contact rows drawn a frame (among the bodies drawn).
constexpr std::size_t kMaxContactRows = 2000;
/// Most pairs a frame whose reference is computed (the item's pair first).
constexpr std::size_t kMaxReferencePairs = 200;

/// What write_view wrote.
struct ViewPage {
  std::string path;            ///< the page (out_dir / file name)
  std::size_t bytes = 0;       ///< its size
  std::size_t bodies = 0;      ///< bodies drawn
  std::size_t frames = 0;      ///< frames on the slider
  std::int64_t frame = 0;      ///< the frame shown first
  std::string note;            ///< what the page notes ("" none): a pair not in contact, a cap
};

/// Writes the page of `trace` (see the file comment) into folder `out_dir` (created when
/// absent). Throws InputError (exit 2) naming the argument: the trace the hardened reader
/// refuses (its message: file, dataset, problem, allowed), `--frame` outside the trace,
/// `--pair` / `--body` naming a body that does not exist (or a pair of one body),
/// `--window` out of range; RuntimeError when libjs-three is missing under
/// settings.three_dir or the page cannot be written (it is written beside its name
/// and renamed, atomic_file.hpp; a FIFO, device, folder or link at its name is InputError). A pair without a contact row in the
/// frame is drawn, with a note on the page and in ViewPage::note.
ViewPage write_view(const std::string& trace, const ViewSettings& settings, const std::string& out_dir);

}  // namespace octocd
