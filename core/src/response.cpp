// The response stage of the CPU step (design.md section 6), Jacobi style: every contact of a pass reads
// the state the previous pass left (the first: the integrated state); per body, position
// corrections are averaged over its contacts and velocity changes summed, in (a, b)
// order. The CUDA engine's gpu/src/response.cu runs the same terms (octocd::contact_terms)
// and the same per-body order.
#include "octocd/stages.hpp"

#include <algorithm>

namespace octocd {

namespace {

template <class T>
std::uint64_t capacity_bytes(const std::vector<T>& v) {
  return static_cast<std::uint64_t>(v.capacity() * sizeof(T));
}

}  // namespace

std::uint64_t ResponseScratch::memory_bytes() const {
  return capacity_bytes(pass_aabbs) + capacity_bytes(terms) + capacity_bytes(dx_sum) + capacity_bytes(dv_sum) +
         capacity_bytes(count);
}

void pass_contact_terms(const std::vector<Aabb>& boxes, const BodyState& state, const std::vector<Pair>& pairs,
                        const std::vector<std::uint8_t>& confirmed, const ContactParams& params,
                        std::vector<ContactTerms>& terms) {
  terms.resize(pairs.size());
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    if (!confirmed[k]) {
      terms[k] = ContactTerms{};
      continue;
    }
    const Pair p = pairs[k];
    terms[k] = contact_terms(boxes[p.a], boxes[p.b], state.v[p.a], state.v[p.b], state.w[p.a], state.w[p.b],
                             params);
  }
}

void sum_contact_terms(const std::vector<Pair>& pairs, const std::vector<ContactTerms>& terms,
                       ResponseScratch& sums) {
  std::fill(sums.dx_sum.begin(), sums.dx_sum.end(), Vec3{});
  std::fill(sums.dv_sum.begin(), sums.dv_sum.end(), Vec3{});
  std::fill(sums.count.begin(), sums.count.end(), 0u);
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    const ContactTerms& t = terms[k];
    if (!t.pen.hit) continue;  // not confirmed, or Eq. 9: no overlap on an axis
    const Pair p = pairs[k];
    sums.dx_sum[p.a] += t.dx_a;
    sums.dx_sum[p.b] += t.dx_b;
    ++sums.count[p.a];
    ++sums.count[p.b];
    sums.dv_sum[p.a] += t.imp.dv_a;
    sums.dv_sum[p.b] += t.imp.dv_b;
  }
}

void apply_contact_sums(BodyState& state, const ResponseScratch& sums) {
  const std::size_t n = state.size();
  for (std::size_t i = 0; i < n; ++i) {
    if (state.w[i] == 0.0f) continue;
    apply_contact_sums(state.x[i], state.v[i], sums.dx_sum[i], sums.dv_sum[i], sums.count[i]);
  }
}

void contact_records(const std::vector<Pair>& pairs, const std::vector<ContactTerms>& terms,
                     const BodyState& state, std::vector<ContactRecord>& out) {
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    const ContactTerms& t = terms[k];
    if (!t.pen.hit) continue;
    const Pair p = pairs[k];
    ContactRecord rec;
    rec.pair = p;
    rec.normal = t.pen.normal;
    rec.depth = t.pen.depth;
    rec.axis = t.pen.axis;
    rec.v_a = state.v[p.a];
    rec.v_b = state.v[p.b];
    rec.dx_a = t.dx_a;
    rec.dx_b = t.dx_b;
    rec.jn = t.imp.jn;
    rec.jt = t.imp.jt;
    rec.dv_a = t.imp.dv_a;
    rec.dv_b = t.imp.dv_b;
    out.push_back(rec);
  }
}

void respond(const Model& model, BodyState& state, const std::vector<Aabb>& boxes, const std::vector<Pair>& pairs,
             const std::vector<std::uint8_t>& confirmed, const ContactParams& params, ResponseScratch& scratch,
             std::vector<ContactRecord>& contacts) {
  const std::size_t n = state.size();
  contacts.clear();
  scratch.dx_sum.resize(n);
  scratch.dv_sum.resize(n);
  scratch.count.resize(n);
  for (int pass = 0; pass < params.iterations; ++pass) {
    if (pass > 0) {
      scratch.pass_aabbs.resize(n);
      update_world_aabbs(model, state.x, scratch.pass_aabbs);
    }
    pass_contact_terms(pass > 0 ? scratch.pass_aabbs : boxes, state, pairs, confirmed, params, scratch.terms);
    if (pass == 0) contact_records(pairs, scratch.terms, state, contacts);
    sum_contact_terms(pairs, scratch.terms, scratch);
    apply_contact_sums(state, scratch);
  }
}

}  // namespace octocd
