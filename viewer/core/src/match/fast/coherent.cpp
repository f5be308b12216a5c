// Method `coherent`: normal-guided transfer in coherent chunks, after
// StyleBlit (Sýkora et al., Eurographics 2019).
//
// The seeds below, and the pixels no chunk takes, start from their nearest
// source pixel by the chosen feature (the fast search, see the call; for
// normals the patch size is not used). For jittered seed grids of spacing
// 2^L ... 4, 2 (coarse to fine), the pixels not yet assigned are split into
// chunks -- those sharing a nearest seed s (among the 3x3 cells around their
// own) -- and each pixel p of a chunk proposes the source pixel m(s) +
// (p - s): the seed's match shifted by p's offset from the seed, i.e. the
// whole chunk of source copied rigidly. A
// chunk is taken whole when the mean error of its proposals (RMS, the map's
// scale; |dn| for normals; off the source object = 1) is under
// options.coherent_threshold and none of them errs more than twice that.
// Judging the chunk rather than each pixel keeps chunks whole where a few
// pixels sit near the threshold. Errors are on the raw features: a low-passed
// guide (tried: 3x3 and 5x5 masked means) cost 5-9 degrees of true normal
// agreement on the bull for no gain in coherence (bench_coherent).
// Chunks of 16 px and more are judged on a 1-in-4 grid of their pixels.
// Then the chunks grow into the pixels no level took (a forward and a
// backward sweep continuing a neighbour's chunk while under the threshold);
// what is left keeps its nearest match. Last, a refinement (see refine())
// trades the seams between chunks against normal error. Jitter comes from a hash of (seed,
// level, cell): the same options give the same map, and a small threshold
// change only changes the chunks whose error sits near it.
//
// Uniformity u > 0 (StyLit/Ebsynth-style): a seed picks its match among its
// 16 nearest by distance + u * uses / fair_share, where uses counts the
// destination pixels already mapped near that source pixel (true counts from
// the coarser levels plus the footprint of this level's earlier seeds), so one
// good source region is not stamped everywhere. Chunks are still judged whole
// on their error alone (judging each pixel with the penalty, as before, broke
// them up: 12.8 % coherence against 46 % now at u = 0.5, bench_match).
#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <atomic>
#include <cstdint>
#include <cmath>
#include <limits>

#ifdef __AVX2__
#include <immintrin.h>
#endif

#include "engine.hpp"
#include "index_fast.hpp"
#include "nearest.hpp"

namespace veneer::match::fast {

namespace {

// Refinement (o.coherent_smooth = w > 0). The chunks leave a seam every few
// pixels where the source's and the destination's curvatures differ, and the
// pixels no chunk took keep their (speckled) nearest. Each pixel then takes,
// among its current match and every continuation of a 4-neighbour's match
// (shifted by their offset, and by one pixel more each way, so a chunk may
// stretch or shrink with the curvatures), the one that minimises
//     error + w * threshold * (4-neighbours it breaks with),
// "broken" meaning matched more than 1.5 px apart, as eval::evaluate counts
// coherence. Iterated conditional modes on a checkerboard: the pixels of one
// colour change together, in parallel, reading the other colour's matches
// (fixed meanwhile, so the map does not depend on threads); then the other
// colour; after the first round only pixels next to a change are visited.
// Each pixel's cost only falls, so the rounds converge; o.coherent_sweeps
// bounds them (4: the fourth still changes ~5 % of a 178k px map, but 8 or 16
// rounds gave the same coherence and error to 0.2 points, bench_coherent;
// 3 rounds save 2 of 40 ms at 150k px for 0.2-0.4 points less coherence).
// Against the chunks alone, at w = 2 (bull <- orange, truth normals,
// 512x340): coherence 54.7 -> 74.4 %, normal error 2.91 -> 2.68 deg.
// The pixel's own nearest is not offered: offered in the first round it
// changed coherence and mean error by at most 0.1 point and 0.02 deg
// (bench_coherent, all pairs and frames), and without it the nearest is only
// needed at the seeds and the pixels no chunk took (see run_coherent).
#ifdef __AVX2__
// The cheapest of a pixel's proposals (refine(), three channels: normals),
// costed 8 at once, with no branch on the costs: its current match, then per
// 4-neighbour (left, right, up, down) whose continuation no earlier one gave,
// its match continued to the pixel and moved one pixel +x, -x, +y, -y; the
// current match fills the last vector. Cost = |a - source| + lam * (present
// neighbours matched more than 1.5 px from the proposal); outside the source
// box +inf. Ties go to the lowest slot, so the order is the scalar path's
// and the current match stays unless a proposal is strictly cheaper.
// `dense`: the source over its box, 4 floats a pixel, off the object far away.
cv::Point cheapest3(const float* a, const float* dense, cv::Size box, const cv::Point* pos,
                    const std::array<int, 4>& nbr, cv::Point current, float lam) {
  alignas(32) int px[24], py[24];
  int count = 0;
  auto push = [&](int x, int y) { px[count] = x, py[count] = y, ++count; };
  push(current.x, current.y);
  static constexpr int n4x[4] = {-1, 1, 0, 0}, n4y[4] = {0, 0, -1, 1};
  int nmx[4], nmy[4], bx[4], by[4], nb = 0;
  for (int j = 0; j < 4; ++j) {
    if (nbr[j] < 0) continue;
    nmx[j] = pos[nbr[j]].x, nmy[j] = pos[nbr[j]].y;
    const int x = nmx[j] - n4x[j], y = nmy[j] - n4y[j];
    bool seen = false;
    for (int t = 0; t < nb; ++t) seen = seen || (bx[t] == x && by[t] == y);
    if (seen) continue;  // the same chunk continued from two sides
    bx[nb] = x, by[nb++] = y;
    push(x, y);
    push(x + 1, y);
    push(x - 1, y);
    push(x, y + 1);
    push(x, y - 1);
  }
  const int vectors = (count + 7) / 8;
  while (count < 8 * vectors) push(current.x, current.y);
  const __m256 a0 = _mm256_set1_ps(a[0]), a1 = _mm256_set1_ps(a[1]), a2 = _mm256_set1_ps(a[2]);
  const __m256i w = _mm256_set1_epi32(box.width), h = _mm256_set1_epi32(box.height), two = _mm256_set1_epi32(2);
  const __m256i minus1 = _mm256_set1_epi32(-1);
  const __m256 vlam = _mm256_set1_ps(lam), inf = _mm256_set1_ps(std::numeric_limits<float>::infinity());
  // costs kept in memory for the final scan, and their running minimum (an
  // array of vectors zero-filled first costs a `rep stos` per pixel)
  alignas(32) float cost[24];
  __m256 m = inf;
  for (int v = 0; v < vectors; ++v) {
    const __m256i x = _mm256_load_si256(reinterpret_cast<const __m256i*>(px + 8 * v));
    const __m256i y = _mm256_load_si256(reinterpret_cast<const __m256i*>(py + 8 * v));
    const __m256i inside = _mm256_and_si256(_mm256_and_si256(_mm256_cmpgt_epi32(x, minus1), _mm256_cmpgt_epi32(w, x)),
                                            _mm256_and_si256(_mm256_cmpgt_epi32(y, minus1), _mm256_cmpgt_epi32(h, y)));
    // each proposal's 4 floats by one load (gathers are slow on many cores),
    // then transposed to x, y, z vectors, lane i = proposal 8v + i
    alignas(32) int at[8];
    _mm256_store_si256(reinterpret_cast<__m256i*>(at),
                       _mm256_and_si256(inside, _mm256_slli_epi32(_mm256_add_epi32(_mm256_mullo_epi32(y, w), x), 2)));
    const __m256 r0 = _mm256_set_m128(_mm_loadu_ps(dense + at[4]), _mm_loadu_ps(dense + at[0]));
    const __m256 r1 = _mm256_set_m128(_mm_loadu_ps(dense + at[5]), _mm_loadu_ps(dense + at[1]));
    const __m256 r2 = _mm256_set_m128(_mm_loadu_ps(dense + at[6]), _mm_loadu_ps(dense + at[2]));
    const __m256 r3 = _mm256_set_m128(_mm_loadu_ps(dense + at[7]), _mm_loadu_ps(dense + at[3]));
    const __m256 t0 = _mm256_unpacklo_ps(r0, r1), t1 = _mm256_unpackhi_ps(r0, r1);
    const __m256 t2 = _mm256_unpacklo_ps(r2, r3), t3 = _mm256_unpackhi_ps(r2, r3);
    const __m256 d0 = _mm256_sub_ps(a0, _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0)));
    const __m256 d1 = _mm256_sub_ps(a1, _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2)));
    const __m256 d2 = _mm256_sub_ps(a2, _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0)));
    const __m256 err = _mm256_sqrt_ps(_mm256_fmadd_ps(d0, d0, _mm256_fmadd_ps(d1, d1, _mm256_mul_ps(d2, d2))));
    __m256i breaks = _mm256_setzero_si256();  // minus the count
    for (int j = 0; j < 4; ++j) {
      if (nbr[j] < 0) continue;
      const __m256i dx = _mm256_sub_epi32(_mm256_set1_epi32(nmx[j]), x);
      const __m256i dy = _mm256_sub_epi32(_mm256_set1_epi32(nmy[j]), y);
      const __m256i d2i = _mm256_add_epi32(_mm256_mullo_epi32(dx, dx), _mm256_mullo_epi32(dy, dy));
      breaks = _mm256_add_epi32(breaks, _mm256_cmpgt_epi32(d2i, two));
    }
    const __m256 pairs = _mm256_mul_ps(vlam, _mm256_cvtepi32_ps(_mm256_sub_epi32(_mm256_setzero_si256(), breaks)));
    const __m256 c = _mm256_blendv_ps(inf, _mm256_add_ps(err, pairs), _mm256_castsi256_ps(inside));
    _mm256_store_ps(cost + 8 * v, c);
    m = _mm256_min_ps(m, c);
  }
  m = _mm256_min_ps(m, _mm256_permute2f128_ps(m, m, 1));
  m = _mm256_min_ps(m, _mm256_shuffle_ps(m, m, _MM_SHUFFLE(1, 0, 3, 2)));
  m = _mm256_min_ps(m, _mm256_shuffle_ps(m, m, _MM_SHUFFLE(2, 3, 0, 1)));
  for (int v = 0; v < vectors; ++v) {
    const int hit = _mm256_movemask_ps(_mm256_cmp_ps(_mm256_load_ps(cost + 8 * v), m, _CMP_EQ_OQ));
    if (hit) {
      const int i = 8 * v + std::countr_zero(static_cast<unsigned>(hit));
      return {px[i], py[i]};
    }
  }
  return current;
}
#endif

// The source's values densely over its bounding box, channels + 1 floats a
// pixel (4 for normals, for cheapest3's loads): the values, then 0 on the
// object; off the object every float is far away (1e4), so that a proposal
// there errs more than any on it. Reading it costs one cache miss where the
// row image and the rows cost two. `coherent` keeps its matches as
// positions in the box packed in an int (x + y * 2^16; -1 none), and needs
// the source's rows only for the nearest.
struct DenseSource {
  std::vector<float> v;
  int stride = 0, channels = 0;
  cv::Rect box;  // of the source, in the image
  const float* at(int x, int y) const {  // x, y relative to box
    return v.data() + (static_cast<size_t>(y) * box.width + x) * stride;
  }
  const float* at(cv::Point q) const { return at(q.x, q.y); }
  bool inside(cv::Point q) const {
    return static_cast<unsigned>(q.x) < static_cast<unsigned>(box.width) &&
           static_cast<unsigned>(q.y) < static_cast<unsigned>(box.height);
  }
  bool on(cv::Point q) const { return at(q)[channels] == 0.0f; }  // on the object (q inside)
  static int pack(cv::Point q) { return q.x | (q.y << 16); }
  static cv::Point unpack(int packed) { return {packed & 0xffff, packed >> 16}; }
  cv::Point local(cv::Point in_image) const { return in_image - box.tl(); }  // an image position in the box
  cv::Point in_image(int packed) const { return unpack(packed) + box.tl(); }
};

DenseSource dense_source(const Object& src, int threads) {
  DenseSource d;
  const int cc = src.channels;
  d.channels = cc;
  d.stride = cc + 1;
  d.box = src.bbox;
  const cv::Rect sb = src.bbox;
  d.v.resize(static_cast<size_t>(sb.area()) * d.stride);
  parallel_rows(sb.height, threads, 16, [&](int b, int e) {
    for (int y = b; y < e; ++y) {
      const int* row = src.row_of.ptr<int>(sb.y + y) + sb.x;
      float* out = d.v.data() + static_cast<size_t>(y) * sb.width * d.stride;
      for (int x = 0; x < sb.width; ++x, out += d.stride) {
        if (row[x] < 0) {
          std::fill_n(out, d.stride, 1e4f);
          continue;
        }
        std::copy_n(src.flat.data() + static_cast<size_t>(row[x]) * cc, cc, out);
        std::fill(out + cc, out + d.stride, 0.0f);
      }
    }
  });
  return d;
}

template <int C>  // the channel count, or 0: any
Status refine(const Object& dst, const Object& src, const DenseSource& dense, const MatchOptions& o, const Progress& p,
              std::vector<int>& chosen) {  // chosen: packed positions
  const int n = dst.rows(), cc = C > 0 ? C : dst.channels;
  const float lam = static_cast<float>(o.coherent_smooth * o.coherent_threshold);
  const cv::Point n4[4] = {{-1, 0}, {1, 0}, {0, -1}, {0, 1}};
  // every match as a position in the dense source: a proposal costs one read
  const cv::Rect sb = src.bbox;
  std::vector<cv::Point> pos(n);
  std::vector<std::array<int, 4>> nbr(n);  // 4-neighbour rows (-1 off the object)
  parallel_rows(n, o.threads, 4096, [&](int b, int e) {
    for (int d = b; d < e; ++d) {
      const cv::Point pt = dst.pixels[d];
      for (int j = 0; j < 4; ++j) nbr[d][j] = dst.row_at(pt.x + n4[j].x, pt.y + n4[j].y);
      pos[d] = DenseSource::unpack(chosen[d]);
    }
  });
  // to visit: all at first; then the pixels next to a change, all of the
  // other colour, so marking them does not touch the pixels being visited
  std::vector<uint8_t> visit(n, 1);
  for (int round = 0; round < o.coherent_sweeps; ++round) {
    if (p.cancelled()) return make_error("cancelled during coherent transfer");
    p.report(0.9 + 0.1 * round / o.coherent_sweeps, "coherent refinement");
    std::atomic<int> changed{0};
    for (int colour = 0; colour < 2; ++colour) {
      parallel_rows(n, o.threads, 2048, [&](int b, int e) {
        int local = 0;
        for (int d = b; d < e; ++d) {
          const cv::Point pt = dst.pixels[d];
          if (((pt.x + pt.y) & 1) != colour || !visit[d]) continue;
          visit[d] = 0;
          cv::Point best_q = pos[d];
          // Settled: all four neighbours continue this match exactly (a
          // chunk's inside) and it errs less than lam. Every other position
          // lies over 1.5 px from one neighbour's match, so costs at least
          // lam: nothing can be cheaper, and the pixel is skipped unread.
          {
            bool settled = true;
            for (int j = 0; j < 4 && settled; ++j)
              settled = nbr[d][j] >= 0 && pos[nbr[d][j]] == best_q + n4[j];
            if (settled && squared_distance(dst.flat.data() + static_cast<size_t>(d) * cc,
                                   dense.at(best_q.x, best_q.y), cc) < lam * lam)
              continue;
          }
#ifdef __AVX2__
          if constexpr (C == 3) {
            best_q = cheapest3(dst.flat.data() + static_cast<size_t>(d) * 3, dense.v.data(), sb.size(), pos.data(),
                               nbr[d], best_q, lam);
          } else
#endif
          {
          cv::Point nm[4];
          int nh = 0;
          for (int j = 0; j < 4; ++j)
            if (nbr[d][j] >= 0) nm[nh++] = pos[nbr[d][j]];
          const float* a = dst.flat.data() + static_cast<size_t>(d) * cc;
          float best = std::numeric_limits<float>::max();
          // A proposal's cost: lam per neighbour it breaks with, plus its
          // error (off the source object larger than any on it). The neighbour
          // term first: it often rules a proposal out before the source is read.
          auto offer = [&](cv::Point q) {
            if (static_cast<unsigned>(q.x) >= static_cast<unsigned>(sb.width) ||
                static_cast<unsigned>(q.y) >= static_cast<unsigned>(sb.height))
              return;
            float pairs = 0;
            for (int j = 0; j < nh; ++j) {
              const int dx = nm[j].x - q.x, dy = nm[j].y - q.y;
              pairs += dx * dx + dy * dy > 2 ? lam : 0.0f;  // integer positions: > 1.5 px
            }
            const float room = best - pairs;
            if (!(room > 0)) return;
            const float e2 = squared_distance(a, dense.at(q.x, q.y), cc);
            if (e2 >= room * room) return;
            const float t = std::sqrt(e2) + pairs;
            if (t < best) best = t, best_q = q;
          };
          offer(best_q);  // the current match first: only a strictly lower cost replaces it
          cv::Point bases[4];
          int nb = 0;
          for (int j = 0; j < 4; ++j) {
            const int q = nbr[d][j];
            if (q < 0) continue;
            const cv::Point base = pos[q] - n4[j];
            bool seen = false;
            for (int t = 0; t < nb; ++t) seen = seen || bases[t] == base;
            if (seen) continue;  // the same chunk continued from two sides
            bases[nb++] = base;
            offer(base);
            offer(base + cv::Point(1, 0));
            offer(base + cv::Point(-1, 0));
            offer(base + cv::Point(0, 1));
            offer(base + cv::Point(0, -1));
          }
          }
          if (best_q != pos[d]) {
            pos[d] = best_q;
            ++local;
            for (int j = 0; j < 4; ++j)
              if (nbr[d][j] >= 0) std::atomic_ref<uint8_t>(visit[nbr[d][j]]).store(1, std::memory_order_relaxed);
          }
        }
        changed.fetch_add(local, std::memory_order_relaxed);
      });
    }
    if (changed.load() == 0) break;
  }
  parallel_rows(n, o.threads, 4096, [&](int b, int e) {
    for (int d = b; d < e; ++d) chosen[d] = DenseSource::pack(pos[d]);
  });
  return {};
}

}  // namespace

Expected<Map> run_coherent(const Object& dst, const Object& src, const MatchOptions& o, const Progress& p,
                           Stats* stats) {
  const float u = static_cast<float>(o.uniformity);
  // Without uniformity a seed takes its nearest source pixel: choosing among
  // its 8 or 32 nearest the one that fits the whole chunk best gained at most
  // 2 points of coherence at equal normal error for 3-6x the time (bench_coherent).
  const int k = u > 0 ? std::min(16, src.rows()) : 1;
  const double cap = 2.0;  // no pixel of an accepted chunk errs more than cap x threshold
  const int n = dst.rows(), c = dst.channels;
  // Normals: the lookup (rarely misses a nearer row across a cell edge, see
  // default_index()). Intensities: the exact nearest whatever the index
  // (nearest.cpp; an approximate one cost coherent 0.09 dB of relighting
  // PSNR on bull <- sphere-red-gloss, 17.85 against 17.94, bench_quality).
  // Without uniformity only the seeds and the pixels no chunk took need
  // their nearest (`near`, by destination row; -1 not asked yet). Normals
  // then ask the lookup for those rows only, when they come to need it:
  // 37 % of the rows at 150k px (bull <- orange), 1.6 ms less of ~40 (the
  // seeds' queries, being sparse, cost twice as much each, bench_match).
  const bool on_demand = u <= 0 && c == 3 && dst.patch == 1;
  NearestLists nn;
  OctGridIndex grid;
  std::vector<int> near;
  if (on_demand) {
    grid.build(src.flat.data(), src.rows(), 3);
    near.assign(n, -1);
    if (stats)
      stats->index = "lookup", stats->projected_dims = 0, stats->certified = 0, stats->explained_variance = 1;
  } else {
    if (auto s = nearest_lists(dst, src, k, default_index(), o.threads, p, nn, stats); !s) return s.error();
    if (u <= 0) near = std::move(nn.ids);  // k = 1
  }
  // the nearest of `rows` (rows whose nearest is not known yet)
  auto ask = [&](const std::vector<int>& rows) -> Status {
    if (!on_demand) return {};
    return nearest_rows(grid, dst, rows.data(), static_cast<int>(rows.size()), o.threads, p, near.data(), nullptr,
                        false);
  };
  const float thr2 = static_cast<float>(o.coherent_threshold * o.coherent_threshold);
  const cv::Rect sb = src.bbox;
  if (sb.width > 65536 || sb.height > 32768)  // DenseSource::pack: x in 16 bits, y in 15
    return make_error("coherent: the source object spans " + std::to_string(sb.width) + "x" +
                      std::to_string(sb.height) + " px; at most 65536x32768 can be matched");
  const DenseSource dense = dense_source(src, o.threads);
  auto dense_sq = [&](int d, int offset) {  // squared feature distance to the dense source at an offset
    return squared_distance(dst.flat.data() + static_cast<size_t>(d) * c,
                   dense.v.data() + static_cast<size_t>(offset) * dense.stride, c);
  };
  auto point_sq = [&](int d, cv::Point q) {  // the same at a position in the box
    return squared_distance(dst.flat.data() + static_cast<size_t>(d) * c, dense.at(q), c);
  };
  auto packed_sq = [&](int d, int packed) { return point_sq(d, DenseSource::unpack(packed)); };
  auto packed_row = [&](int row) { return DenseSource::pack(dense.local(src.pixels[row])); };  // a source row's
  // the match of every destination row, as a packed position (-1: none yet)
  std::vector<int> chosen(n, -1);
  // the rows still unassigned, and per one of them its chunk (seed cell),
  // proposal and error at the current level
  std::vector<int> active(n), owner(n), prop(n);
  for (int d = 0; d < n; ++d) active[d] = d;
  // The places in `active` of its pixels on a level's judging grid (see
  // `sampled`), kept while `active` stays the same: the coarse levels often
  // take nothing (bull <- orange at 150k px: none of 256 ... 32), and then
  // iterate over a sixteenth of the pixels instead of all.
  std::vector<int> on_grid;
  int on_grid_mask = 0;  // of the grid on_grid holds; 0: none
  const cv::Rect box = dst.bbox;
  int spacing = 2;
  while (spacing * 2 <= std::max(box.width, box.height) / 2 && spacing < 256) spacing *= 2;
  const float area = static_cast<float>(dst.patch * dst.patch);
  const float fair = std::max(1e-6f, static_cast<float>(n) / static_cast<float>(src.rows()));
  std::vector<int> uses;
  // Row's candidate of least cost -- its distance plus the reuse penalty for
  // the source pixel's uses so far -- or -1 when it has none.
  auto least_cost = [&](int row) {
    float best = std::numeric_limits<float>::infinity();
    int pick = -1;
    for (int m = 0; m < k; ++m) {
      const int id = nn.ids[static_cast<size_t>(row) * k + m];
      if (id < 0) break;
      const cv::Point q = src.pixels[id];
      const float cost = std::sqrt(nn.sq[static_cast<size_t>(row) * k + m] / area) +
                         u * static_cast<float>(uses[static_cast<size_t>(q.y) * src.size.width + q.x]) / fair;
      if (cost < best) best = cost, pick = id;
    }
    return pick;
  };
  if (u > 0) uses.assign(static_cast<size_t>(src.size.area()), 0);

  for (int level = 0; spacing >= 2; ++level, spacing /= 2) {
    if (p.cancelled()) return make_error("cancelled during coherent transfer");
    p.report(0.5 + 0.4 * std::min(level, 8) / 8.0, "coherent chunks");
    const int s = spacing, shift = std::countr_zero(static_cast<unsigned>(spacing));  // a power of two
    const int gx = box.width / s + 1, gy = box.height / s + 1;
    // Seeds: one jittered point per cell; its destination row and source match.
    std::vector<cv::Point> seed_at(static_cast<size_t>(gx) * gy);
    std::vector<int> seed_match(seed_at.size(), -1), seed_row(u <= 0 ? seed_at.size() : 0, -1);
    // seed rows [jb, je); in parallel unless the reuse counts chain them
    auto make_seeds = [&](int jb, int je) {
    for (int j = jb; j < je; ++j)
      for (int i = 0; i < gx; ++i) {
        const uint64_t r = hash3(o.seed, static_cast<uint64_t>(level), static_cast<uint64_t>(j) * gx + i);
        const cv::Point at(box.x + i * s + static_cast<int>((r & 0xffff) % s),
                           box.y + j * s + static_cast<int>(((r >> 16) & 0xffff) % s));
        const size_t cell = static_cast<size_t>(j) * gx + i;
        seed_at[cell] = at;
        const int row = dst.row_at(at.x, at.y);
        if (row < 0) continue;
        if (u <= 0) {
          seed_row[cell] = row;  // its match once its nearest is known
          continue;
        }
        if (const int pick = least_cost(row); pick >= 0) seed_match[cell] = pick;
        // this chunk's footprint, until the true counts replace it
        const cv::Point q = src.pixels[seed_match[cell]];
        for (int y = std::max(0, q.y - s / 2); y < std::min(src.size.height, q.y + s / 2 + 1); ++y)
          for (int x = std::max(0, q.x - s / 2); x < std::min(src.size.width, q.x + s / 2 + 1); ++x)
            ++uses[static_cast<size_t>(y) * src.size.width + x];
      }
    };
    if (u <= 0) {
      parallel_rows(gy, o.threads, 4, make_seeds);
      std::vector<int> rows;
      rows.reserve(seed_row.size());
      for (const int r : seed_row)
        if (r >= 0 && near[r] < 0) rows.push_back(r);
      if (auto st = ask(rows); !st) return st.error();
      for (size_t cell = 0; cell < seed_row.size(); ++cell)
        if (seed_row[cell] >= 0) seed_match[cell] = near[seed_row[cell]];
    } else {
      make_seeds(0, gy);
    }
    {
      // Chunks: the unassigned pixels sharing a nearest seed. Each seed's
      // source position is the one of its nearest normals (kc of them) that
      // fits its whole chunk best (mean error, off-object = 1); the chunk is
      // taken whole when that mean passes the threshold and no pixel in it
      // errs more than `cap` times the threshold.
      // (k = 1: one proposal per pixel, so no per-chunk lists are needed)
      // Over the pixels still unassigned (`active`), in parallel. The chunk
      // sums are kept in fixed point (errors in [0, 1] times 2^20) so that
      // they come out the same whatever order the threads add in.
      const size_t seeds = seed_at.size();
      std::vector<std::atomic<uint64_t>> sum(seeds);
      std::vector<std::atomic<uint32_t>> worst(seeds), cnt(seeds);
      const int na = static_cast<int>(active.size());
      // Chunks of 16 px and more are judged on the pixels of a 1-in-4 grid
      // (x and y multiples of 4): a sixteenth of the source reads where most
      // chunks fail, and still hundreds of pixels per chunk. Chunks of 8 px
      // on a 1-in-2 grid (x and y even; ~16 pixels a chunk): at 150k px
      // 0.3-1 ms less, coherence 0.2-0.7 points more and normal error
      // 0.03-0.07 deg more than judging every pixel (orange, stone -> bull).
      const int grid_mask = s >= 16 ? 3 : s == 8 ? 1 : 0;  // judged where (x | y) & grid_mask == 0
      const bool sampled = grid_mask != 0;
      if (sampled && on_grid_mask != grid_mask) {
        on_grid.clear();
        for (int ai = 0; ai < static_cast<int>(active.size()); ++ai) {
          const cv::Point pt = dst.pixels[active[ai]];
          if (((pt.x | pt.y) & grid_mask) == 0) on_grid.push_back(ai);
        }
        on_grid_mask = grid_mask;
      }
      // the places in `active` judged at this level: on the grid, or all
      const int nj = sampled ? static_cast<int>(on_grid.size()) : na;
      auto judged = [&](int i) { return sampled ? on_grid[i] : i; };
      // The seeds on a grid padded by one cell all round; a seed off the
      // object, and the padding, sit far away (cell -1), so that finding a
      // pixel's nearest seed needs neither bounds checks nor branches.
      const int pgx = gx + 2;
      struct PaddedSeed {
        int x, y, cell;
      };
      constexpr int far = -(1 << 29);  // squared distances in 64 bits: no overflow for any image
      std::vector<PaddedSeed> padded(static_cast<size_t>(pgx) * (gy + 2), PaddedSeed{far, far, -1});
      for (int j = 0; j < gy; ++j)
        for (int i = 0; i < gx; ++i) {
          const int cell = j * gx + i;
          if (seed_match[cell] >= 0) padded[(j + 1) * pgx + i + 1] = {seed_at[cell].x, seed_at[cell].y, cell};
        }
      // the seed whose chunk pixel pt is in: the nearest of the 3x3 cells'
      // seeds (the first in row order among equals), -1 if none is on the object
      auto owner_of = [&](cv::Point pt) {
        const int ci = (pt.x - box.x) >> shift, cj = (pt.y - box.y) >> shift;
        int best_cell = -1;
        int64_t best_d2 = std::numeric_limits<int64_t>::max();
        for (int j = 0; j < 3; ++j) {
          const PaddedSeed* row = &padded[static_cast<size_t>(cj + j) * pgx + ci];
          for (int i = 0; i < 3; ++i) {
            const int64_t dx = row[i].x - pt.x, dy = row[i].y - pt.y, d2 = dx * dx + dy * dy;
            const bool nearer = d2 < best_d2;
            best_d2 = nearer ? d2 : best_d2;
            best_cell = nearer ? row[i].cell : best_cell;
          }
        }
        return best_cell;
      };
      parallel_rows(nj, o.threads, sampled ? 4096 : 16384, [&](int b, int e) {
        // first each judged pixel's chunk and the source position it
        // proposes (prop: its offset in the dense source, -1 outside the
        // source's box, -2 none; both by judged place i), then the source
        // reads, each a cache miss: prefetched a few pixels ahead. The chunk
        // sums are added when the chunk changes along the row (runs of a few
        // pixels at the finest).
        for (int i = b; i < e; ++i) {
          const cv::Point pt = dst.pixels[active[judged(i)]];
          prop[i] = -2;
          const int best_cell = owner_of(pt);
          owner[i] = best_cell;
          if (best_cell < 0) continue;
          const cv::Point m = src.pixels[seed_match[best_cell]];
          const cv::Point a = seed_at[best_cell];
          const int x = m.x + pt.x - a.x - sb.x, y = m.y + pt.y - a.y - sb.y;
          prop[i] = x < 0 || y < 0 || x >= sb.width || y >= sb.height ? -1 : y * sb.width + x;
        }
        constexpr int ahead = 8;
        int run = -1;
        uint64_t run_sum = 0;
        uint32_t run_cnt = 0, run_worst = 0;
        auto flush = [&] {
          if (run < 0) return;
          sum[run].fetch_add(run_sum, std::memory_order_relaxed);
          cnt[run].fetch_add(run_cnt, std::memory_order_relaxed);
          uint32_t w = worst[run].load(std::memory_order_relaxed);
          while (run_worst > w && !worst[run].compare_exchange_weak(w, run_worst, std::memory_order_relaxed)) {
          }
        };
        for (int i = b; i < e; ++i) {
          if (i + ahead < e && prop[i + ahead] >= 0)
            __builtin_prefetch(dense.v.data() + static_cast<size_t>(prop[i + ahead]) * dense.stride);
          const int c0 = owner[i];
          if (c0 < 0) continue;
          // off the source's box 1; off the object min(1, far) = 1 as well
          const float err = prop[i] < 0 ? 1.0f : std::min(1.0f, std::sqrt(dense_sq(active[judged(i)], prop[i])));
          const uint32_t q = static_cast<uint32_t>(err * 1048576.0f);
          if (c0 != run) {
            flush();
            run = c0, run_sum = 0, run_cnt = 0, run_worst = 0;
          }
          run_sum += q, ++run_cnt, run_worst = std::max(run_worst, q);
        }
        flush();
      });
      const double thr = o.coherent_threshold * 1048576.0;
      std::vector<uint8_t> taken(seeds, 0);
      std::atomic<bool> any{false};
      parallel_rows(static_cast<int>(seeds), o.threads, 8192, [&](int b, int e) {
        bool some = false;
        for (int c = b; c < e; ++c) {
          const uint32_t judged = cnt[c].load(std::memory_order_relaxed);
          taken[c] = judged > 0 && static_cast<double>(sum[c].load(std::memory_order_relaxed)) / judged < thr &&
                     worst[c].load(std::memory_order_relaxed) < cap * thr;
          some = some || taken[c];
        }
        if (some) any.store(true, std::memory_order_relaxed);
      });
      // (a level that takes no chunk, often the coarsest, ends here)
      if (any.load()) {
        // Judged on the grid: per cell, whether a taken chunk's seed is among
        // its 3x3 cells, i.e. whether a pixel there can be in one; the
        // pixels there look for their seed again (owner[] is by judged place).
        std::vector<uint8_t> near_taken;
        if (sampled) {
          near_taken.assign(static_cast<size_t>(gx) * gy, 0);
          for (int j = 0; j < gy; ++j)
            for (int i = 0; i < gx; ++i)
              if (taken[static_cast<size_t>(j) * gx + i])
                for (int y = std::max(0, j - 1); y <= std::min(gy - 1, j + 1); ++y)
                  for (int x = std::max(0, i - 1); x <= std::min(gx - 1, i + 1); ++x) near_taken[y * gx + x] = 1;
        }
        parallel_rows(na, o.threads, 1024, [&](int b, int e) {
          for (int ai = b; ai < e; ++ai) {
            const cv::Point pt = dst.pixels[active[ai]];
            int c0;
            if (sampled) {
              if (!near_taken[((pt.y - box.y) >> shift) * gx + ((pt.x - box.x) >> shift)]) continue;
              c0 = owner_of(pt);
            } else {
              c0 = owner[ai];
            }
            if (c0 < 0 || !taken[c0]) continue;
            const cv::Point m = src.pixels[seed_match[c0]], a = seed_at[c0];
            const cv::Point q = dense.local(m + pt - a);
            if (dense.inside(q) && dense.on(q)) chosen[active[ai]] = DenseSource::pack(q);
          }
        });
        // the pixels still unassigned, in row order
        size_t kept = 0;
        for (int ai = 0; ai < na; ++ai)
          if (chosen[active[ai]] < 0) active[kept++] = active[ai];
        active.resize(kept);
        on_grid_mask = 0;
      }
    }
    if (u > 0) {
      std::fill(uses.begin(), uses.end(), 0);
      for (int d = 0; d < n; ++d)
        if (chosen[d] >= 0) {
          const cv::Point q = dense.in_image(chosen[d]);
          ++uses[static_cast<size_t>(q.y) * src.size.width + q.x];
        }
    }
  }
  // The chunks then grow into the pixels none took: sweeping forward (from
  // the left and upper neighbours) and back (right, lower), a pixel continues
  // the neighbour's chunk whose proposal errs least, if under the threshold.
  if (o.coherent_grow && !active.empty()) {
    const float t2 = thr2;
    for (int sweep = 0; sweep < 2; ++sweep) {
      const int step = sweep == 0 ? 1 : -1;
      const int na = static_cast<int>(active.size());
      for (int i = 0; i < na; ++i) {
        const int d = active[sweep == 0 ? i : na - 1 - i];
        if (chosen[d] >= 0 && sweep == 0) continue;
        const cv::Point pt = dst.pixels[d];
        float best = chosen[d] >= 0 ? packed_sq(d, chosen[d]) : t2;
        for (const cv::Point off : {cv::Point(-step, 0), cv::Point(0, -step)}) {
          const int nb = dst.row_at(pt.x + off.x, pt.y + off.y);
          if (nb < 0 || chosen[nb] < 0) continue;
          const cv::Point q = DenseSource::unpack(chosen[nb]) - off;
          if (!dense.inside(q) || !dense.on(q)) continue;
          const float v = point_sq(d, q);
          if (v < best) best = v, chosen[d] = DenseSource::pack(q);
        }
      }
    }
  }
  // Pixels no chunk took keep their nearest; with uniformity, the nearest of
  // their 16 by distance + reuse penalty (live counts, scan order).
  if (u <= 0) {
    std::vector<int> rows;
    for (int d = 0; d < n; ++d)
      if (chosen[d] < 0 && near[d] < 0) rows.push_back(d);
    if (auto st = ask(rows); !st) return st.error();
  }
  for (int d = 0; d < n; ++d) {
    if (chosen[d] >= 0) continue;
    if (u <= 0) {
      chosen[d] = packed_row(near[d]);
      continue;
    }
    const int pick = least_cost(d);
    if (pick >= 0) {
      chosen[d] = packed_row(pick);
      const cv::Point q = src.pixels[pick];
      ++uses[static_cast<size_t>(q.y) * src.size.width + q.x];
    }
  }
  if (o.coherent_smooth > 0) {
    const auto t0 = std::chrono::steady_clock::now();
    const Status r = c == 3 ? refine<3>(dst, src, dense, o, p, chosen) : refine<0>(dst, src, dense, o, p, chosen);
    if (!r) return r.error();
    if (stats) stats->refine_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  Map map = new_map(dst.size);
  parallel_rows(n, o.threads, 4096, [&](int b, int e) {
    for (int d = b; d < e; ++d) {
      if (chosen[d] < 0) continue;
      const cv::Point pt = dst.pixels[d], q = dense.in_image(chosen[d]);
      map.xy.at<cv::Vec2f>(pt.y, pt.x) = cv::Vec2f(static_cast<float>(q.x), static_cast<float>(q.y));
      map.distance.at<float>(pt.y, pt.x) = std::sqrt(packed_sq(d, chosen[d]));  // the feature distance
    }
  });
  return map;
}

}  // namespace veneer::match::fast
