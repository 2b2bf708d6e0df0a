// The judging of an external trace (validate_external_trace, octocd/external.hpp): a check
// pass over every frame through core's external-trace reader (core/src/trace_in.hpp), which
// keeps the frames the run judges, then the frames handed to an ExternalValidator, the next
// one read on a second thread while one is judged; shards, soft-contact episodes across
// their borders, stops and the verdicts so far.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/exact_pairs.hpp"  // PairLimitError
#include "octocd/external.hpp"
#include "octocd/shard_spec.hpp"
#include "trace_in.hpp"  // core/src (private include)

namespace octocd {

namespace {

/// The bytes a decoded record holds in its arrays (the check pass's budget for the frames
/// it keeps).
std::size_t record_bytes(const FrameRecord& r) {
  return sizeof(FrameRecord) +
         (r.x_pre.size() + r.v_pre.size() + r.x_post.size() + r.v_post.size() + r.w_pre.size() + r.w_post.size() +
          r.x_det.size() + r.jt3.size()) *
             sizeof(Vec3) +
         (r.q_pre.size() + r.q_post.size() + r.q_det.size()) * sizeof(Quat) + r.aabbs.size() * sizeof(Aabb) +
         (r.pairs.size() + r.confirmed.size()) * sizeof(Pair) + r.contacts.size() * sizeof(ContactRecord) +
         r.asleep_pre.size() + r.asleep_post.size();
}

/// At most this many bytes of decoded frames are kept from the check pass for the judging
/// (the frames beyond are decoded a second time, as the judging reaches them).
constexpr std::size_t kKeptFrameBytes = std::size_t(256) << 20;

/// The frames the check pass decoded that the judging takes instead of decoding them again:
/// frames first .. first + records.size() - 1, each taken once.
struct KeptFrames {
  std::int64_t max_frames = 0;  ///< the frames judged: 1 .. max_frames (0: all) ...
  ShardSpec shard;              ///< ... this shard's block of them, which is kept
  std::int64_t first = 1;
  std::vector<FrameRecord> records;
  detail::TraceIn::RecordSettings settings;  ///< what the records were read with
  bool has(std::int64_t f) const { return f >= first && f - first < static_cast<std::int64_t>(records.size()); }
  FrameRecord take(std::int64_t f) { return std::move(records[static_cast<std::size_t>(f - first)]); }
};

/// Every frame's values checked with a reader that does not parse the scene (as
/// --check-only); `stop` (may be empty) polled between frames. With `keep`: the frames its
/// run judges are kept as decoded, from the first on, up to kKeptFrameBytes, and
/// `keep->settings` says what they were read with. The reader is closed on return.
ExternalTraceInfo check_frames(const std::string& path, const std::function<bool()>& stop,
                               KeptFrames* keep = nullptr, bool recorded = false) {
  detail::TraceIn in(path, false, recorded, recorded);
  std::int64_t last = 0;
  if (keep) {
    const std::int64_t run = keep->max_frames > 0 ? std::min(keep->max_frames, in.info.frames) : in.info.frames;
    std::tie(keep->first, last) = shard_frames(keep->shard, run);
  }
  std::size_t bytes = 0;
  bool keeping = keep != nullptr;
  in.check_frames(
      [&stop] {
        if (stop && stop()) throw ValidationStopped();
      },
      [&](std::int64_t f, FrameRecord&& rec) {
        if (!keeping || f < keep->first) return;
        bytes += record_bytes(rec);
        keeping = f <= last && bytes <= kKeptFrameBytes;
        if (keeping) keep->records.push_back(std::move(rec));
      });
  if (keep) keep->settings = in.record_settings();
  return in.info;
}

}  // namespace

std::vector<ValidationResult> validate_external_trace(const std::string& path, ExternalOptions options, int every,
                                                      std::int64_t max_frames, ExternalTraceInfo* info) {
  if (every < 1) throw InputError(fmt::format("--every: {}; allowed: >= 1", every));
  // The trace is decoded once: the check pass (every frame's values, before any verdict)
  // keeps the frames this run judges (the shard's block, or frames 1 .. --frames), up to
  // kKeptFrameBytes, and the judging takes them instead of reading them again.
  KeptFrames kept;
  kept.max_frames = max_frames;
  kept.shard = options.shard;
  // States every K-th frame are read as recorded (TraceStates::Recorded): each step is
  // judged on what it carries.
  const ExternalTraceInfo checked = check_frames(path, options.stop, &kept, true);
  detail::TraceIn in(path, true, true, true);
  if (!in.same_records(kept.settings)) kept.records.clear();  // an "integrated" pose from the scene's dt and gravity
  options.engine = in.info.engine;
  options.spec6_response = in.info.spec6_response;
  options.octocd_engine = in.info.octocd_conventions;  // declared by the trace's layout, never by its engine name
  // With a scene, the bodies come from it and the trace's tables must match it.
  // The bodies' declarations are checked against the scene's shapes where the validators
  // are built: an error about them names the file and its dataset.
  auto named = [&](const InputError& e) {
    std::string what = e.what();
    const std::string field = "PhysicsBodies.collision_shape";
    const std::size_t at = what.find(field);
    if (at == std::string::npos || in.bodies.physics.collision_shape.empty()) throw;  // as it came
    what.replace(at, field.size(), "/bodies/collision_shape (or the root attribute collision_shape)");
    throw InputError(fmt::format("{}: {}", path, what));
  };
  std::unique_ptr<ExternalValidator> made;
  const std::int64_t frames = max_frames > 0 ? std::min(max_frames, in.info.frames) : in.info.frames;
  std::int64_t judged_to = 0, judging = 0;  // the last frame judged whole; the frame in its checks
  constexpr std::chrono::milliseconds kSnapshotEvery{20};  // options.on_judged's pace
  std::chrono::steady_clock::time_point last_snapshot{};
  bool stopped = false;
  try {
    made = std::make_unique<ExternalValidator>(in.bodies, options);
    if (options.on_judged) {  // judging begins: the verdict of no whole frame
      ExternalTraceInfo now = checked;
      now.frames = frames;
      now.judged_to = 0;
      options.on_judged(made->results(), now);
    }
    // A shard judges its block of the run's frames; checked frames keep the run's numbering.
    // Frame f + 1 is read (HDF5, on a second thread: the only one that calls HDF5 meanwhile)
    // while frame f is judged.
    const auto [first, last] = shard_frames(options.shard, frames);
    // A shard of soft contacts: the energy of an isolated group is judged over its contact
    // episode, which may cross the shard's borders. The shard judges the episodes that
    // begin in its frames: it follows the episodes through the frames before its own
    // (those open at its first frame began in an earlier shard, which judges them) and
    // reads on past its last frame until its own episodes have closed, so the merged
    // verdict equals the whole run's.
    const bool episodes = options.shard.count > 1 && made->judges_episodes() && first <= last && !in.pose_only();
    if (episodes) {
      made->set_episode_frames(first, last);
      for (std::int64_t f = 1; f < first; ++f) {
        if (options.stop && options.stop()) throw ValidationStopped();
        made->observe_episodes(in.frame(f));
      }
    }
    // A frame the check pass kept is taken as it is; another is read on the second thread.
    auto fetch = [&in, &kept](std::int64_t f) {
      if (kept.has(f)) return std::async(std::launch::deferred, [&kept, f] { return kept.take(f); });
      return std::async(std::launch::async, [&in, f] { return in.frame(f); });
    };
    // With sparse states only the steps whose pre-step state is recorded (each checked:
    // they are already one in K).
    auto next_posed = [&in, last](std::int64_t f) {
      while (f <= last && !in.posed(f)) ++f;
      return f;
    };
    std::future<FrameRecord> next;
    std::int64_t f = next_posed(first);
    if (f <= last) next = fetch(f);
    for (; f <= last;) {
      if (options.stop && options.stop()) throw ValidationStopped();
      const FrameRecord rec = next.get();
      const std::int64_t after = next_posed(f + 1);
      if (after <= last) next = fetch(after);
      judging = f;
      made->observe(rec, in.pose_only() || f % every == 0);
      judged_to = std::min(after - 1, last);  // the steps skipped up to the next posed one are done
      judging = 0;
      if (options.on_judged &&
          (f == next_posed(first) || std::chrono::steady_clock::now() - last_snapshot >= kSnapshotEvery)) {
        ExternalTraceInfo now = checked;
        now.frames = frames;
        now.judged_to = judged_to;
        options.on_judged(made->results(), now);
        last_snapshot = std::chrono::steady_clock::now();
      }
      f = after;
    }
    if (first <= last && next_posed(first) > last) judged_to = last;
    for (std::int64_t later = last + 1; episodes && later <= frames && made->episodes_pending(); ++later) {
      if (options.stop && options.stop()) throw ValidationStopped();
      made->observe_episodes(in.frame(later));
    }
  } catch (const PairLimitError& e) {
    throw PairLimitError(fmt::format("{}: {}", path, e.what()), e);  // "T: frame F: ..."
  } catch (const InputError& e) {
    named(e);
  } catch (const ValidationStopped&) {
    if (!options.keep_on_stop || !made) throw;
    stopped = true;  // the verdict of the frames judged so far
  }
  ExternalValidator& validator = *made;
  std::vector<ValidationResult> results = validator.results();
  apply_trace_plan(results, plan_trace_rows(checked, in.bodies));
  if (info) {
    *info = checked;
    info->frames = frames;
    info->judged_to = judged_to;
    info->stopped_in = judging;
    info->stopped = stopped;
  }
  return results;
}

}  // namespace octocd
