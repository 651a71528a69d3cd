//
// Tests of the sample sequences of a pixel (yocto_sampling.h): the shuffled
// Owen-scrambled Sobol pairs (Burley, Practical Hash-based Owen Scrambling,
// JCGT 2020) keep the (0,2)-sequence property on every aligned range of
// samples, are uniform, deterministic, independent across pixels and pairs,
// and beat independent numbers on a smooth integrand; the global Sobol point
// (Joe and Kuo's directions, one Owen scramble per dimension) is a net on
// every pair of its 32 dimensions with the t its generator matrices promise,
// across pairs as well as within one. Every statistical test
// uses fixed seeds and states its sample count and tolerance.
//

#include <gtest/gtest.h>
#include <yocto/yocto_sampling.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <vector>

using namespace yocto;

// -----------------------------------------------------------------------------
// HELPERS
// -----------------------------------------------------------------------------

// Enough Sobol pairs for every pair index used below.
static const auto test_sobol_pairs = 64;

// Pair `pair` of sample `sample` of a pixel, from a fresh state.
static vec2f sequence_point(sequence_type type, uint64_t seed, int64_t pixel,
    uint32_t sample, int pair) {
  auto state = make_sequence(type, seed, pixel, sample, test_sobol_pairs);
  return sample_sequence2f(state, pair);
}

// Samples first .. first + count - 1 of a pair of a pixel.
static std::vector<vec2f> sequence_points(sequence_type type, uint64_t seed,
    int64_t pixel, uint32_t first, int count, int pair) {
  auto points = std::vector<vec2f>(count);
  for (auto s = 0; s < count; s++) {
    points[s] = sequence_point(type, seed, pixel, first + (uint32_t)s, pair);
  }
  return points;
}

// Whether 2^k points have exactly one point in every elementary interval
// [i / 2^a, (i + 1) / 2^a) x [j / 2^b, (j + 1) / 2^b) with a + b = k: a
// (0,k,2)-net in base 2.
static testing::AssertionResult is_02_net(const std::vector<vec2f>& points, int k) {
  auto n = 1 << k;
  if ((int)points.size() != n)
    return testing::AssertionFailure() << points.size() << " points, not 2^" << k;
  auto counts = std::vector<int>(n);
  for (auto a = 0; a <= k; a++) {
    auto b = k - a;
    std::fill(counts.begin(), counts.end(), 0);
    for (auto& p : points) {
      // Scaling by a power of two is exact: the floor is the interval.
      auto i = (int)std::floor(p.x * (float)(1 << a));
      auto j = (int)std::floor(p.y * (float)(1 << b));
      if (i < 0 || i >= (1 << a) || j < 0 || j >= (1 << b))
        return testing::AssertionFailure() << "point (" << p.x << ", " << p.y
                                           << ") outside [0, 1)^2";
      counts[(i << b) + j]++;
    }
    for (auto cell = 0; cell < n; cell++) {
      if (counts[cell] != 1)
        return testing::AssertionFailure()
               << "split 2^" << a << " x 2^" << b << ": interval (" << (cell >> b)
               << ", " << (cell & ((1 << b) - 1)) << ") holds " << counts[cell]
               << " points";
    }
  }
  return testing::AssertionSuccess();
}

// Upper tail P(X >= chi2) of a chi-square variable with `dof` degrees of
// freedom, by the Wilson-Hilferty cube-root normal approximation (accurate to
// about 1e-3 in p for dof >= 10).
static double chi_square_pvalue(double chi2, int dof) {
  auto k = (double)dof;
  auto z = (std::cbrt(chi2 / k) - (1 - 2 / (9 * k))) / std::sqrt(2 / (9 * k));
  return 0.5 * std::erfc(z / std::sqrt(2.0));
}

// Chi-square statistic of histogram counts against a uniform expectation.
static double chi_square(const std::vector<int>& counts) {
  auto total = 0.0;
  for (auto c : counts) total += c;
  auto expected = total / counts.size();
  auto chi2     = 0.0;
  for (auto c : counts) chi2 += (c - expected) * (c - expected) / expected;
  return chi2;
}

// Pearson correlation coefficient of two equally long series.
static double correlation(const std::vector<double>& x, const std::vector<double>& y) {
  auto n  = (double)x.size();
  auto mx = 0.0, my = 0.0;
  for (auto i = 0; i < (int)x.size(); i++) mx += x[i], my += y[i];
  mx /= n, my /= n;
  auto sxy = 0.0, sxx = 0.0, syy = 0.0;
  for (auto i = 0; i < (int)x.size(); i++) {
    sxy += (x[i] - mx) * (y[i] - my);
    sxx += (x[i] - mx) * (x[i] - mx);
    syy += (y[i] - my) * (y[i] - my);
  }
  return sxy / std::sqrt(sxx * syy);
}

static uint32_t float_bits(float x) {
  auto bits = 0u;
  std::memcpy(&bits, &x, sizeof(bits));
  return bits;
}

// -----------------------------------------------------------------------------
// BIT OPERATIONS AND SCRAMBLING
// -----------------------------------------------------------------------------

TEST(sampling, reverse_bits_hand_values) {
  EXPECT_EQ(reverse_bits(0u), 0u);
  EXPECT_EQ(reverse_bits(1u), 0x80000000u);
  EXPECT_EQ(reverse_bits(2u), 0x40000000u);
  EXPECT_EQ(reverse_bits(3u), 0xC0000000u);
  EXPECT_EQ(reverse_bits(0x80000000u), 1u);
  EXPECT_EQ(reverse_bits(0xFFFFFFFFu), 0xFFFFFFFFu);
  EXPECT_EQ(reverse_bits(0x0000FFFFu), 0xFFFF0000u);
  EXPECT_EQ(reverse_bits(0x12345678u), 0x1E6A2C48u);
  // An involution, bit by bit.
  auto rng = make_rng(11);
  for (auto t = 0; t < 1000; t++) {
    auto x = advance_rng(rng), r = reverse_bits(x);
    EXPECT_EQ(reverse_bits(r), x);
    for (auto bit = 0; bit < 32; bit++) {
      ASSERT_EQ((x >> bit) & 1, (r >> (31 - bit)) & 1) << std::hex << x;
    }
  }
}

TEST(sampling, sobol_dimensions_hand_values) {
  // Dimension 0 is the van der Corput sequence 0, 1/2, 1/4, 3/4, 1/8, ...
  auto dimension0 = std::vector<uint32_t>{
      0, 0x80000000u, 0x40000000u, 0xC0000000u, 0x20000000u};
  for (auto i = 0; i < (int)dimension0.size(); i++)
    EXPECT_EQ(sobol_dimension0(i), dimension0[i]) << i;
  // Dimension 1: 0, 1/2, 3/4, 1/4, 5/8, 1/8, 3/8, 7/8.
  auto dimension1 = std::vector<uint32_t>{0, 0x80000000u, 0xC0000000u, 0x40000000u,
      0xA0000000u, 0x20000000u, 0x60000000u, 0xE0000000u};
  for (auto i = 0; i < (int)dimension1.size(); i++)
    EXPECT_EQ(sobol_dimension1(i), dimension1[i]) << i;
}

TEST(sampling, sobol_dimension1_matches_pascal_matrix) {
  // Direction number k has digit j (from the top) set iff C(k, j) is odd,
  // that is (Lucas) iff j & k == j; this is v_k = v_{k-1} ^ (v_{k-1} >> 1).
  auto directions = std::vector<uint32_t>(32);
  for (auto k = 0; k < 32; k++) {
    for (auto j = 0; j <= k; j++) {
      if ((j & k) == j) directions[k] |= 1u << (31 - j);
    }
  }
  EXPECT_EQ(directions[0], 0x80000000u);
  for (auto k = 1; k < 32; k++)
    EXPECT_EQ(directions[k], directions[k - 1] ^ (directions[k - 1] >> 1)) << k;
  auto reference = [&](uint32_t index) {
    auto result = 0u;
    for (auto k = 0; k < 32; k++)
      if ((index >> k) & 1) result ^= directions[k];
    return result;
  };
  for (auto index = 0u; index < 4096; index++)
    ASSERT_EQ(sobol_dimension1(index), reference(index)) << index;
  auto rng = make_rng(5);
  for (auto t = 0; t < 1000; t++) {
    auto index = advance_rng(rng);
    ASSERT_EQ(sobol_dimension1(index), reference(index)) << index;
  }
}

TEST(sampling, nested_uniform_scramble_permutes_top_bits) {
  // Owen scrambling flips each digit of a 0.32 fixed-point number by a
  // function of the digits above it, so the top 16 bits of the result depend
  // on the top 16 bits of the argument alone, and bijectively.
  for (auto seed : {0u, 1u, 0x9e3779b9u, 0xdeadbeefu}) {
    auto seen = std::vector<bool>(1 << 16, false);
    for (auto x = 0u; x < (1u << 16); x++) {
      auto top = nested_uniform_scramble(x << 16, seed) >> 16;
      ASSERT_FALSE(seen[top]) << "seed " << seed << ": " << x << " collides";
      seen[top] = true;
    }
  }
  // The same holds for every prefix length k: changing the low 32 - k bits
  // never changes the top k bits of the result.
  auto rng = make_rng(3);
  for (auto t = 0; t < 2000; t++) {
    auto seed = advance_rng(rng), x = advance_rng(rng), noise = advance_rng(rng);
    auto k    = 1 + rand1i(rng, 31);
    auto low  = (1u << (32 - k)) - 1;
    auto y    = (x & ~low) | (noise & low);
    ASSERT_EQ(nested_uniform_scramble(x, seed) & ~low,
        nested_uniform_scramble(y, seed) & ~low)
        << "k " << k;
  }
}

TEST(sampling, sample_sobol2f_is_burley_listing) {
  // Burley 2020, section 4: shuffle the index with a nested uniform scramble,
  // take the two Sobol dimensions, scramble each with its own seed. The
  // header saves two bit reversals per dimension; the result must not change.
  auto rng = make_rng(17);
  for (auto t = 0; t < 2000; t++) {
    auto seed     = ((uint64_t)advance_rng(rng) << 32) | advance_rng(rng);
    auto index    = t < 1000 ? (uint32_t)t : advance_rng(rng);
    auto hash     = hash_uint64(seed);
    auto more     = hash_uint64(hash);
    auto shuffled = nested_uniform_scramble(index, (uint32_t)hash);
    auto x = nested_uniform_scramble(sobol_dimension0(shuffled), (uint32_t)(hash >> 32));
    auto y = nested_uniform_scramble(sobol_dimension1(shuffled), (uint32_t)more);
    auto point = sample_sobol2f(index, seed);
    ASSERT_EQ(float_bits(point.x), float_bits(fixed_to_float(x))) << index;
    ASSERT_EQ(float_bits(point.y), float_bits(fixed_to_float(y))) << index;
  }
}

TEST(sampling, chi_square_pvalue_matches_tables) {
  // Table values: chi2(10) = 18.307 and chi2(100) = 124.342 at p = 0.05,
  // chi2(63) = 103.442 at p = 0.001; and the median is about dof - 2/3.
  EXPECT_NEAR(chi_square_pvalue(18.307, 10), 0.05, 0.002);
  EXPECT_NEAR(chi_square_pvalue(124.342, 100), 0.05, 0.002);
  EXPECT_NEAR(chi_square_pvalue(103.442, 63), 0.001, 0.0002);
  EXPECT_NEAR(chi_square_pvalue(255 - 2.0 / 3, 255), 0.5, 0.002);
}

// -----------------------------------------------------------------------------
// (0,2)-SEQUENCE
// -----------------------------------------------------------------------------

TEST(sampling, sobol_pairs_are_02_sequences) {
  // For 2^k points, k = 0..12: the first 2^k samples and the aligned blocks
  // of samples [m 2^k, (m + 1) 2^k) for m = 3 and m = 1000, so that any
  // aligned sample range renders alone and stays stratified.
  for (auto seed : {(uint64_t)0, (uint64_t)1, (uint64_t)0x5eed1234abcdULL}) {
    for (auto pixel : {(int64_t)0, (int64_t)1, (int64_t)640 * 37 + 501}) {
      for (auto pair : {0, 1, 7, 40}) {
        for (auto k = 0; k <= 12; k++) {
          auto n = 1 << k;
          for (auto m : {0u, 3u, 1000u}) {
            auto points = sequence_points(
                sequence_type::sobol, seed, pixel, m * (uint32_t)n, n, pair);
            ASSERT_TRUE(is_02_net(points, k))
                << "seed " << seed << " pixel " << pixel << " pair " << pair
                << " samples " << m * n << ".." << (m + 1) * n - 1;
          }
        }
      }
    }
  }
}

// Whether 2^k points have 2^t points in every elementary interval of area
// 2^(t - k) of the projection on dimensions d0 and d1: a (t,k,2)-net.
static bool is_t_net(const std::vector<vec4f>& points, int d0, int d1, int k, int t) {
  auto cells  = 1 << (k - t);
  auto counts = std::vector<int>(cells);
  for (auto a = 0; a <= k - t; a++) {
    auto b = k - t - a;
    std::fill(counts.begin(), counts.end(), 0);
    for (auto& p : points) {
      auto i = (int)std::floor(p[d0] * (float)(1 << a));
      auto j = (int)std::floor(p[d1] * (float)(1 << b));
      if (i < 0 || i >= (1 << a) || j < 0 || j >= (1 << b)) return false;
      counts[(i << b) + j]++;
    }
    for (auto count : counts)
      if (count != 1 << t) return false;
  }
  return true;
}

TEST(sampling, sobol4_points_are_jointly_stratified) {
  // Sobol dimensions 2 and 3 by hand: 0, 1/2, 3/4, 1/4, 3/8, 7/8, 5/8, 1/8
  // and 0, 1/2, 3/4, 1/4, 1/8, 5/8, 7/8, 3/8 (their direction numbers 1/2,
  // 3/4, 3/8 and 1/2, 3/4, 1/8).
  auto dimension2 = std::vector<float>{0, 0.5f, 0.75f, 0.25f, 0.375f, 0.875f, 0.625f, 0.125f};
  auto dimension3 = std::vector<float>{0, 0.5f, 0.75f, 0.25f, 0.125f, 0.625f, 0.875f, 0.375f};
  for (auto i = 0u; i < 8; i++) {
    EXPECT_EQ(sobol_reversed(sobol_dimension2_tables, i), reverse_bits((uint32_t)(
                                                               dimension2[i] * 4294967296.0)))
        << i;
    EXPECT_EQ(sobol_reversed(sobol_dimension3_tables, i), reverse_bits((uint32_t)(
                                                               dimension3[i] * 4294967296.0)))
        << i;
  }
  // For 2^k points, k = 0..10, the first ones and the aligned blocks m 2^k
  // for m = 3 and 1000, three seeds: dimensions 0 and 1 are sample_sobol2f's
  // point bit for bit (a (0,2)-sequence); every pair of the four dimensions
  // is a (t,k,2)-net with t <= 2 (the largest t measured over these pairs
  // and sizes); each dimension alone has one point in every 1 / 2^k.
  for (auto seed : {(uint64_t)0, (uint64_t)1, (uint64_t)0x5eed1234abcdULL}) {
    for (auto k = 0; k <= 10; k++) {
      auto n = 1 << k;
      for (auto m : {0u, 3u, 1000u}) {
        auto points = std::vector<vec4f>(n);
        for (auto s = 0; s < n; s++) {
          auto index = m * (uint32_t)n + (uint32_t)s;
          points[s]  = sample_sobol4f(index, seed);
          auto pair  = sample_sobol2f(index, seed);
          ASSERT_EQ(points[s].x, pair.x);
          ASSERT_EQ(points[s].y, pair.y);
        }
        for (auto d0 = 0; d0 < 4; d0++) {
          auto strata = std::vector<int>(n);
          for (auto& p : points) strata[(int)std::floor(p[d0] * (float)n)]++;
          ASSERT_TRUE(std::all_of(strata.begin(), strata.end(), [](int c) { return c == 1; }))
              << "dimension " << d0 << " k " << k;
          for (auto d1 = d0 + 1; d1 < 4; d1++) {
            auto t = d0 == 0 && d1 == 1 ? 0 : std::min(2, k);
            ASSERT_TRUE(is_t_net(points, d0, d1, k, t))
                << "seed " << seed << " dimensions " << d0 << " " << d1 << " k " << k
                << " block " << m;
          }
        }
      }
    }
  }
  // Not vacuous: dimensions 2 and 3 of 64 points are no (0,6,2)-net, and
  // other seeds give other points.
  auto points = std::vector<vec4f>(64);
  for (auto s = 0; s < 64; s++) points[s] = sample_sobol4f((uint32_t)s, 7);
  EXPECT_FALSE(is_t_net(points, 2, 3, 6, 0));
  EXPECT_NE(sample_sobol4f(5, 7).z, sample_sobol4f(5, 8).z);
}

TEST(sampling, sequence4f_takes_two_pairs) {
  // Where both pairs are Sobol pairs, the four numbers are one 4D Sobol
  // point (the same for the same sample, whatever was drawn before); past
  // them, the pairs' own numbers (Sobol, then the generator's).
  auto state  = make_sequence(sequence_type::sobol, 3, 17, 5, 4);
  auto first  = sample_sequence4f(state, 1);
  auto again  = make_sequence(sequence_type::sobol, 3, 17, 5, 4);
  sample_sequence2f(again, 0);
  EXPECT_EQ(sample_sequence4f(again, 1), first);
  auto edge = make_sequence(sequence_type::sobol, 3, 17, 5, 4);
  auto last = sample_sequence4f(edge, 3);
  auto pair = make_sequence(sequence_type::sobol, 3, 17, 5, 4);
  EXPECT_EQ(last.x, sample_sequence2f(pair, 3).x);
  EXPECT_EQ(last.y, sample_sequence2f(pair, 3).y);
  for (auto value : {last.x, last.y, last.z, last.w}) {
    EXPECT_GE(value, 0.0f);
    EXPECT_LT(value, 1.0f);
  }
}

// -----------------------------------------------------------------------------
// GLOBAL SOBOL
// -----------------------------------------------------------------------------

// Dimension `dimension` of point `index` of the global sequence scrambled by
// `key`, as sample_sobol_global2f returns it (slot dimension / 2).
static float global_point(uint32_t index, uint64_t key, int dimension) {
  auto p = sample_sobol_global2f(index, key, dimension / 2);
  return dimension % 2 == 0 ? p.x : p.y;
}

// Rank over GF(2) of rows of bits.
static int gf2_rank(std::vector<uint32_t> rows) {
  auto rank = 0;
  for (auto bit = 0; bit < 32 && rank < (int)rows.size(); bit++) {
    auto pivot = -1;
    for (auto r = rank; r < (int)rows.size(); r++)
      if (rows[r] >> bit & 1) pivot = r;
    if (pivot < 0) continue;
    std::swap(rows[rank], rows[pivot]);
    for (auto r = 0; r < (int)rows.size(); r++)
      if (r != rank && (rows[r] >> bit & 1)) rows[r] ^= rows[rank];
    rank++;
  }
  return rank;
}

// Row `digit` (0 the most significant) of a dimension's generator matrix
// over the first k bits of the index: bit j set where direction j has the
// digit.
static uint32_t generator_row(int dimension, int digit, int k) {
  auto row = 0u;
  for (auto j = 0; j < k; j++)
    if (sobol_global_directions[dimension][j] >> digit & 1) row |= 1u << j;
  return row;
}

// The smallest t for which the unscrambled projection of 2^k points onto
// dimensions d0 and d1 is a (t,k,2)-net: the first a digits of d0 and b of
// d1 are independent functions of the index for every a + b = k - t (Niederreiter's
// criterion), computed from the direction numbers alone.
static int net_quality(int d0, int d1, int k) {
  for (auto t = 0; t <= k; t++) {
    auto independent = true;
    for (auto a = 0; a <= k - t && independent; a++) {
      auto rows = std::vector<uint32_t>{};
      for (auto i = 0; i < a; i++) rows.push_back(generator_row(d0, i, k));
      for (auto i = 0; i < k - t - a; i++) rows.push_back(generator_row(d1, i, k));
      independent = gf2_rank(rows) == (int)rows.size();
    }
    if (independent) return t;
  }
  return k;
}

TEST(sampling, global_sobol_directions_match_joe_kuo) {
  // Dimension 0 is van der Corput's, 1 to 3 the tables of the pairs and the
  // 4D points; the first 16 points of dimensions 4, 17 and 31 (times 16) as
  // SciPy 1.10's unscrambled Sobol (qmc.Sobol(d=32, scramble=False), which
  // reads the same new-joe-kuo-6.21201 file) gives them, in its Gray-code
  // order (its point i is our point i ^ (i >> 1)).
  for (auto index = 0u; index < 4096; index++) {
    ASSERT_EQ(sobol_global_reversed(0, index), index) << index;
    ASSERT_EQ(sobol_global_reversed(1, index), sobol_reversed(sobol_dimension1_tables, index));
    ASSERT_EQ(sobol_global_reversed(2, index), sobol_reversed(sobol_dimension2_tables, index));
    ASSERT_EQ(sobol_global_reversed(3, index), sobol_reversed(sobol_dimension3_tables, index));
  }
  auto scipy = std::vector<std::pair<int, std::array<uint32_t, 16>>>{
      {4, {0, 8, 12, 4, 6, 14, 10, 2, 9, 1, 5, 13, 15, 7, 3, 11}},
      {17, {0, 8, 4, 12, 14, 6, 10, 2, 13, 5, 9, 1, 3, 11, 7, 15}},
      {31, {0, 8, 4, 12, 2, 10, 6, 14, 13, 5, 9, 1, 15, 7, 11, 3}},
  };
  for (auto& [dimension, sixteenths] : scipy) {
    for (auto index = 0u; index < 16; index++)
      EXPECT_EQ(reverse_bits(sobol_global_reversed(dimension, index ^ (index >> 1))) >> 28,
          sixteenths[index])
          << "dimension " << dimension << " point " << index;
  }
  // No two dimensions are the same (a pair of them would be no net at all).
  for (auto d0 = 0; d0 < sobol_global_dimensions; d0++)
    for (auto d1 = d0 + 1; d1 < sobol_global_dimensions; d1++)
      EXPECT_NE(sobol_global_directions[d0], sobol_global_directions[d1]) << d0 << " " << d1;
}

TEST(sampling, global_sobol_projections_are_nets) {
  // For 2^k points, k = 0..10, the first ones and the aligned blocks of
  // samples m 2^k (m = 3 and 1000, so that any aligned range of samples
  // renders alone stratified), two keys: every one of the 32 dimensions has
  // one point in every 1 / 2^k, and every pair of dimensions (496 pairs,
  // across slots as well as within one) is a (t,k,2)-net with the t of its
  // generator matrices, which the scramble keeps. The promise: dimensions 0
  // and 1 (the pixel) t = 0, every pair of the first 16 dimensions t <= 5,
  // of all 32 t <= 6 (measured maxima for k = 10; the shuffled pairs of
  // sequence_type::sobol have no such bound across pairs).
  auto worst = std::array<int, 2>{0, 0};  // first 16 dimensions, all 32
  for (auto key : {(uint64_t)0, (uint64_t)0x5eed1234abcdULL}) {
    for (auto k = 0; k <= 10; k++) {
      auto n = 1 << k;
      for (auto m : {0u, 3u, 1000u}) {
        auto points = std::vector<std::array<float, sobol_global_dimensions>>(n);
        for (auto s = 0; s < n; s++)
          for (auto d = 0; d < sobol_global_dimensions; d++)
            points[s][d] = global_point(m * (uint32_t)n + (uint32_t)s, key, d);
        for (auto d0 = 0; d0 < sobol_global_dimensions; d0++) {
          auto strata = std::vector<int>(n);
          for (auto& p : points) {
            ASSERT_TRUE(p[d0] >= 0 && p[d0] < 1) << p[d0];
            strata[(int)(p[d0] * (float)n)]++;
          }
          ASSERT_TRUE(std::all_of(strata.begin(), strata.end(), [](int c) { return c == 1; }))
              << "dimension " << d0 << " k " << k << " block " << m;
          for (auto d1 = d0 + 1; d1 < sobol_global_dimensions; d1++) {
            auto t = net_quality(d0, d1, k);
            if (d1 < 16) worst[0] = std::max(worst[0], t);
            worst[1] = std::max(worst[1], t);
            auto pairs = std::vector<vec4f>(n);
            for (auto s = 0; s < n; s++) pairs[s] = {points[s][d0], points[s][d1], 0, 0};
            ASSERT_TRUE(is_t_net(pairs, 0, 1, k, t))
                << "dimensions " << d0 << " " << d1 << " k " << k << " t " << t << " block "
                << m << " key " << key;
            // Not vacuous: where t > 0 the projection is no finer net.
            if (t > 0 && m == 0) {
              ASSERT_FALSE(is_t_net(pairs, 0, 1, k, t - 1))
                  << "dimensions " << d0 << " " << d1 << " k " << k << " t " << t;
            }
          }
        }
      }
    }
  }
  EXPECT_EQ(net_quality(0, 1, 10), 0);
  EXPECT_LE(worst[0], 5);
  EXPECT_LE(worst[1], 6);
  EXPECT_GT(worst[1], 0);  // the criterion finds t > 0 somewhere
}

TEST(sampling, global_sobol_sequence_takes_slots) {
  // A pair with a slot draws that slot's dimensions of the global point; a
  // pair with slot -1 draws the shuffled Sobol pair of sequence_type::sobol;
  // pairs past sobol_pairs the stream, and pairs past the list of slots
  // (global_pairs, 5 here: the 9 is not read) are padded. Without slots
  // global_sobol is sobol.
  auto slots = std::array<int8_t, 6>{0, -1, 5, 1, 15, 9};
  for (auto pixel : {(int64_t)0, (int64_t)777}) {
    for (auto s : {0u, 9u, 4000u}) {
      auto global = make_sequence(sequence_type::global_sobol, 3, pixel, s, 6, slots.data(), 5);
      auto pairs  = make_sequence(sequence_type::sobol, 3, pixel, s, 6);
      auto plain  = make_sequence(sequence_type::global_sobol, 3, pixel, s, 6);
      for (auto pair = 0; pair < 8; pair++) {
        auto point = sample_sequence2f(global, pair);
        auto other = sample_sequence2f(pairs, pair);
        auto same  = sample_sequence2f(plain, pair);
        EXPECT_EQ(float_bits(same.x), float_bits(other.x)) << pair;
        if (pair < 5 && slots[pair] >= 0) {
          auto expected = sample_sobol_global2f(s, global.key, slots[pair]);
          EXPECT_EQ(float_bits(point.x), float_bits(expected.x)) << pair;
          EXPECT_EQ(float_bits(point.y), float_bits(expected.y)) << pair;
          EXPECT_NE(float_bits(point.x), float_bits(other.x)) << pair;
        } else {
          // Padded and stream pairs: the same numbers as the pairs sequence
          // (both states drew the same number of stream pairs so far).
          EXPECT_EQ(float_bits(point.x), float_bits(other.x)) << pair;
          EXPECT_EQ(float_bits(point.y), float_bits(other.y)) << pair;
        }
      }
      // Four numbers from two slotted pairs are the two pairs' points.
      auto four = make_sequence(sequence_type::global_sobol, 3, pixel, s, 6, slots.data(), (int)slots.size());
      auto quad = sample_sequence4f(four, 2);
      auto a    = sample_sobol_global2f(s, four.key, 5);
      auto b    = sample_sobol_global2f(s, four.key, 1);
      EXPECT_EQ(quad, (vec4f{a.x, a.y, b.x, b.y}));
    }
  }
}

TEST(sampling, global_sobol_is_uniform_and_independent_over_pixels) {
  // 4096 pixels x 16 samples, seeds 1 and 2024, slots 0, 7 and 15: the
  // histograms of x, y and (x, y) of uniformity_pvalues, and the joint
  // histogram of x of slot 0 against x of slot 7 (16 x 16 bins, across
  // slots: one point, so jointly stratified too); tolerance p > 0.001 on
  // each of 24 histograms.
  auto slots = std::array<int8_t, 16>{};
  for (auto i = 0; i < 16; i++) slots[i] = (int8_t)i;
  for (auto seed : {(uint64_t)1, (uint64_t)2024}) {
    auto hx = std::array<std::vector<int>, 3>{}, hy = hx, hxy = hx;
    for (auto i = 0; i < 3; i++)
      hx[i] = hy[i] = std::vector<int>(64), hxy[i] = std::vector<int>(256);
    auto across = std::vector<int>(256);
    for (auto pixel = 0; pixel < 4096; pixel++) {
      for (auto s = 0u; s < 16; s++) {
        auto state = make_sequence(sequence_type::global_sobol, seed, pixel, s, 16, slots.data(), (int)slots.size());
        auto zero  = vec2f{};
        for (auto [i, slot] : {std::pair{0, 0}, std::pair{1, 7}, std::pair{2, 15}}) {
          auto p = sample_sequence2f(state, slot);
          if (slot == 0) zero = p;
          if (slot == 7) across[(int)(zero.x * 16) * 16 + (int)(p.x * 16)]++;
          hx[i][(int)(p.x * 64)]++;
          hy[i][(int)(p.y * 64)]++;
          hxy[i][(int)(p.x * 16) * 16 + (int)(p.y * 16)]++;
        }
      }
    }
    for (auto i = 0; i < 3; i++) {
      EXPECT_GT(chi_square_pvalue(chi_square(hx[i]), 63), 0.001) << seed << " " << i << " x";
      EXPECT_GT(chi_square_pvalue(chi_square(hy[i]), 63), 0.001) << seed << " " << i << " y";
      EXPECT_GT(chi_square_pvalue(chi_square(hxy[i]), 255), 0.001) << seed << " " << i << " xy";
    }
    EXPECT_GT(chi_square_pvalue(chi_square(across), 255), 0.001) << seed << " slots 0, 7";
  }
  // Pixels are scrambled apart: no two of 1024 pixels share more than one of
  // their first 16 points of slot 3; other seeds give other points.
  auto points = [&](uint64_t seed, int64_t pixel) {
    auto result = std::vector<vec2f>(16);
    for (auto s = 0u; s < 16; s++) {
      auto state = make_sequence(sequence_type::global_sobol, seed, pixel, s, 16, slots.data(), (int)slots.size());
      result[s]  = sample_sequence2f(state, 3);
    }
    return result;
  };
  auto first = points(5, 0);
  for (auto pixel = 1; pixel < 1024; pixel++) {
    auto other = points(5, pixel);
    auto same  = 0;
    for (auto i = 0; i < 16; i++) same += other[i] == first[i];
    EXPECT_LE(same, 1) << "pixel " << pixel;
  }
  auto reseeded = points(6, 0);
  for (auto i = 0; i < 16; i++) EXPECT_NE(reseeded[i], first[i]) << i;
}

TEST(sampling, global_sobol_points_are_pure_functions) {
  // The same (seed, pixel, sample) gives the same bits whatever was drawn
  // before, in whatever order, and whatever other states drew.
  auto slots = std::array<int8_t, 10>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9};
  for (auto pixel : {0, 77, 1 << 20}) {
    for (auto s : {0u, 1u, 1000u}) {
      auto forward  = make_sequence(sequence_type::global_sobol, 42, pixel, s, 10, slots.data(), (int)slots.size());
      auto backward = make_sequence(sequence_type::global_sobol, 42, pixel, s, 10, slots.data(), (int)slots.size());
      auto first = std::vector<vec2f>(10), second = std::vector<vec2f>(10);
      for (auto pair = 0; pair < 10; pair++) first[pair] = sample_sequence2f(forward, pair);
      for (auto pair = 9; pair >= 0; pair--) second[pair] = sample_sequence2f(backward, pair);
      for (auto pair = 0; pair < 10; pair++) {
        EXPECT_EQ(float_bits(first[pair].x), float_bits(second[pair].x));
        EXPECT_EQ(float_bits(first[pair].y), float_bits(second[pair].y));
      }
    }
  }
}

// RMS error over 256 pixels of the 64-sample estimate of the integral of
// x0 x1 e^(x0 + x1) over [0, 1]^2, x0 from pair 0 and x1 from pair
// `pair` (a function of two pairs, as a bounce's direction and the next
// bounce's are): (integral of x e^x)^2 = 1.
static double integration_rms_error_across(sequence_type type, int pair) {
  auto slots = std::array<int8_t, 16>{};
  for (auto i = 0; i < 16; i++) slots[i] = (int8_t)i;
  auto sum2 = 0.0;
  for (auto pixel = 0; pixel < 256; pixel++) {
    auto estimate = 0.0;
    for (auto s = 0u; s < 64; s++) {
      auto state = make_sequence(type, 77, pixel, s, 16, slots.data(), (int)slots.size());
      auto x0 = (double)sample_sequence2f(state, 0).x;
      auto x1 = (double)sample_sequence2f(state, pair).x;
      estimate += x0 * x1 * std::exp(x0 + x1);
    }
    estimate /= 64;
    sum2 += (estimate - 1) * (estimate - 1);
  }
  return std::sqrt(sum2 / 256);
}

TEST(sampling, global_sobol_beats_pairs_across_pairs) {
  // 64 samples per pixel, 256 pixels; tolerance: the global point's RMS
  // error at least 4 times smaller than the shuffled pairs'. Measured:
  // global 1.02e-2 (pair 1) and 1.36e-2 (pair 9), pairs 9.74e-2 and 9.50e-2
  // (the shuffle leaves the two pairs' joint error at Monte Carlo's rate).
  for (auto pair : {1, 9}) {
    auto pairs  = integration_rms_error_across(sequence_type::sobol, pair);
    auto global = integration_rms_error_across(sequence_type::global_sobol, pair);
    EXPECT_GT(pairs / global, 4) << "pair " << pair << ": global " << global << ", pairs "
                                 << pairs;
  }
}

TEST(sampling, independent_numbers_are_not_nets) {
  // The net check is not vacuous: 256 independent points fail it.
  auto points = sequence_points(sequence_type::independent, 1, 0, 0, 256, 0);
  EXPECT_FALSE(is_02_net(points, 8));
}

// -----------------------------------------------------------------------------
// UNIFORMITY
// -----------------------------------------------------------------------------

// Histograms of pair `pair` over 2^16 points, `samples` samples of each of
// 2^16 / samples pixels starting at sample `first`: 64 bins of x, 64 bins of
// y, 16 x 16 bins of (x, y); p-values of their chi-square statistics (63,
// 63 and 255 degrees of freedom, 1024 and 256 expected counts per bin).
static std::array<double, 3> uniformity_pvalues(
    sequence_type type, uint64_t seed, int pair, uint32_t first, int samples) {
  auto hx = std::vector<int>(64), hy = std::vector<int>(64), hxy = std::vector<int>(256);
  for (auto pixel = 0; pixel < (1 << 16) / samples; pixel++) {
    for (auto s = first; s < first + (uint32_t)samples; s++) {
      auto p = sequence_point(type, seed, pixel, s, pair);
      hx[(int)(p.x * 64)]++;
      hy[(int)(p.y * 64)]++;
      hxy[(int)(p.x * 16) * 16 + (int)(p.y * 16)]++;
    }
  }
  return {chi_square_pvalue(chi_square(hx), 63), chi_square_pvalue(chi_square(hy), 63),
      chi_square_pvalue(chi_square(hxy), 255)};
}

TEST(sampling, sequences_are_uniform) {
  // Tolerance: every p-value > 0.001, 2^16 points per histogram. Sobol: one
  // sample (0 or 1234) of each of 2^16 pixels, so that the scrambles of
  // different pixels are tested against each other; independent numbers:
  // 16 samples of each of 4096 pixels.
  // Measured p (x, y, xy): sobol pair 0: 0.035, 0.14, 0.58 (sample 0) and
  // 0.28, 0.67, 0.88 (sample 1234); pair 5: 0.64, 0.36, 0.25 and 0.87, 0.75,
  // 0.56; pair 63: 0.062, 0.56, 0.087 and 0.80, 0.38, 0.49; independent:
  // 0.54, 0.90, 0.73.
  for (auto pair : {0, 5, 63}) {
    for (auto first : {0u, 1234u}) {
      auto p = uniformity_pvalues(sequence_type::sobol, 2024, pair, first, 1);
      EXPECT_GT(p[0], 0.001) << "sobol pair " << pair << " sample " << first << " x";
      EXPECT_GT(p[1], 0.001) << "sobol pair " << pair << " sample " << first << " y";
      EXPECT_GT(p[2], 0.001) << "sobol pair " << pair << " sample " << first << " xy";
    }
  }
  auto p = uniformity_pvalues(sequence_type::independent, 2024, 0, 0, 16);
  EXPECT_GT(p[0], 0.001) << "independent x";
  EXPECT_GT(p[1], 0.001) << "independent y";
  EXPECT_GT(p[2], 0.001) << "independent xy";
}

// 4096 pixels x 16 samples of pairs 0..15 for seeds 1, 7, 2024; tolerance
// p > 0.001 on each of 144 histograms. With Burley 2020's listing-2 hash (the
// seed enters by one addition only) 5 of the 96 one-dimensional histograms
// failed, worst p = 8.4e-8 (pair 5, seed 2024, x: chi-square 140.7 for 63
// degrees of freedom); with Vegdahl 2021's hash (the header's) the worst p is 0.25.
TEST(sampling, sobol_is_uniform_over_pixels_of_16_samples) {
  for (auto seed : {(uint64_t)1, (uint64_t)7, (uint64_t)2024}) {
    for (auto pair = 0; pair < 16; pair++) {
      auto p = uniformity_pvalues(sequence_type::sobol, seed, pair, 0, 16);
      EXPECT_GT(p[0], 0.001) << "seed " << seed << " pair " << pair << " x";
      EXPECT_GT(p[1], 0.001) << "seed " << seed << " pair " << pair << " y";
      EXPECT_GT(p[2], 0.001) << "seed " << seed << " pair " << pair << " xy";
    }
  }
}

// In an Owen scramble every node of the tree of strata flips its digit
// independently, so where the point of a pixel's stratum [c/16, (c+1)/16)
// lies among its four sub-strata of width 1/64 is independent from stratum
// to stratum. Burley 2020's listing-2 hash adds the seed and then applies
// one fixed permutation, so the top d digits of nested_uniform_scramble take
// only 2^d forms over all seeds (an Owen scramble has 2^(2^d - 1)): the
// sub-stratum in stratum 1 (or 9) was nearly a function of the one in
// stratum 0. 4096 pixels x 16 samples; chi-square of the 4 x 4 joint
// histogram of the two sub-strata (15 degrees of freedom, 256 expected
// counts per cell), tolerance p > 0.001. Measured chi-square: 4100-4130 for
// strata (0, 1), 7100-7470 for (0, 9) with listing 2 (p = 0); with
// Vegdahl 2021's hash: 7-24, p >= 0.067.
TEST(sampling, sobol_substrata_are_independent) {
  for (auto pair : {0, 5, 40}) {
    for (auto axis : {0, 1}) {
      auto joint01 = std::vector<int>(16), joint09 = std::vector<int>(16);
      for (auto pixel = 0; pixel < 4096; pixel++) {
        auto substratum = std::array<int, 16>{};
        for (auto s = 0u; s < 16; s++) {
          auto p = sequence_point(sequence_type::sobol, 2024, pixel, s, pair);
          auto v = axis == 0 ? p.x : p.y;
          substratum[(int)(v * 16)] = (int)(v * 64) & 3;
        }
        joint01[substratum[0] * 4 + substratum[1]]++;
        joint09[substratum[0] * 4 + substratum[9]]++;
      }
      EXPECT_GT(chi_square_pvalue(chi_square(joint01), 15), 0.001)
          << "pair " << pair << " axis " << axis << " strata 0 and 1: chi-square "
          << chi_square(joint01);
      EXPECT_GT(chi_square_pvalue(chi_square(joint09), 15), 0.001)
          << "pair " << pair << " axis " << axis << " strata 0 and 9: chi-square "
          << chi_square(joint09);
    }
  }
}

TEST(sampling, values_are_in_unit_interval) {
  // The largest fixed-point value still maps below 1.
  EXPECT_LT(fixed_to_float(0xFFFFFFFFu), 1.0f);
  EXPECT_EQ(fixed_to_float(0xFFFFFFFFu), 1.0f - 1.0f / 16777216.0f);
  EXPECT_EQ(fixed_to_float(0), 0.0f);
  // 64 pixels x 256 samples x 16 pairs, Sobol and past the Sobol pairs.
  for (auto type : {sequence_type::sobol, sequence_type::independent}) {
    for (auto pixel = 0; pixel < 64; pixel++) {
      for (auto s = 0u; s < 256; s++) {
        auto state = make_sequence(type, 99, pixel, s, 8);
        for (auto pair = 0; pair < 16; pair++) {
          auto p = sample_sequence2f(state, pair);
          ASSERT_TRUE(p.x >= 0 && p.x < 1 && p.y >= 0 && p.y < 1)
              << p.x << " " << p.y << " pair " << pair;
        }
      }
    }
  }
}

// -----------------------------------------------------------------------------
// DETERMINISM
// -----------------------------------------------------------------------------

TEST(sampling, sobol_pairs_do_not_depend_on_call_order) {
  // All ten pairs Sobol: drawing them in order 0..9 or 9..0 gives the same
  // bits, and so does drawing one pair alone in a fresh state.
  for (auto pixel : {0, 77, 1 << 20}) {
    for (auto s : {0u, 1u, 1000u}) {
      auto forward  = make_sequence(sequence_type::sobol, 42, pixel, s, 10);
      auto backward = make_sequence(sequence_type::sobol, 42, pixel, s, 10);
      auto first = std::vector<vec2f>(10), second = std::vector<vec2f>(10);
      for (auto pair = 0; pair < 10; pair++) first[pair] = sample_sequence2f(forward, pair);
      for (auto pair = 9; pair >= 0; pair--) second[pair] = sample_sequence2f(backward, pair);
      for (auto pair = 0; pair < 10; pair++) {
        auto alone = make_sequence(sequence_type::sobol, 42, pixel, s, 10);
        auto point = sample_sequence2f(alone, pair);
        EXPECT_EQ(float_bits(first[pair].x), float_bits(second[pair].x));
        EXPECT_EQ(float_bits(first[pair].y), float_bits(second[pair].y));
        EXPECT_EQ(float_bits(first[pair].x), float_bits(point.x));
        EXPECT_EQ(float_bits(first[pair].y), float_bits(point.y));
      }
    }
  }
}

TEST(sampling, stream_numbers_repeat_for_the_same_calls) {
  // Independent numbers, and pairs past sobol_pairs, come from a stream: the
  // same arguments and call sequence give the same bits; nothing is shared
  // between states (interleaving two states changes nothing).
  for (auto type : {sequence_type::independent, sequence_type::sobol}) {
    for (auto s : {0u, 5u, 123456u}) {
      auto a = make_sequence(type, 7, 300, s, 2);
      auto b = make_sequence(type, 7, 300, s, 2);
      auto other = make_sequence(type, 8, 301, s + 1, 2);
      for (auto pair = 0; pair < 12; pair++) {
        auto pa = sample_sequence2f(a, pair);
        sample_sequence2f(other, pair);
        auto pb = sample_sequence2f(b, pair);
        EXPECT_EQ(float_bits(pa.x), float_bits(pb.x)) << pair;
        EXPECT_EQ(float_bits(pa.y), float_bits(pb.y)) << pair;
      }
    }
  }
  // Independent ignores sobol_pairs.
  auto a = make_sequence(sequence_type::independent, 7, 300, 9, 0);
  auto b = make_sequence(sequence_type::independent, 7, 300, 9, 64);
  for (auto pair = 0; pair < 4; pair++) {
    auto pa = sample_sequence2f(a, pair), pb = sample_sequence2f(b, pair);
    EXPECT_EQ(float_bits(pa.x), float_bits(pb.x));
    EXPECT_EQ(float_bits(pa.y), float_bits(pb.y));
  }
}

TEST(sampling, seeds_give_different_sequences) {
  for (auto type : {sequence_type::sobol, sequence_type::independent}) {
    auto p = sequence_points(type, 1, 10, 0, 16, 0);
    auto q = sequence_points(type, 2, 10, 0, 16, 0);
    auto same = 0;
    for (auto i = 0; i < 16; i++) same += p[i].x == q[i].x && p[i].y == q[i].y;
    EXPECT_EQ(same, 0);
  }
}

// -----------------------------------------------------------------------------
// INDEPENDENCE
// -----------------------------------------------------------------------------

TEST(sampling, pairs_and_pixels_are_uncorrelated) {
  // N = 2^14 samples of one pixel; tolerance |r| < 4 / sqrt(N) = 0.03125
  // (four standard deviations of r for independent series).
  // Measured max |r|: sobol 0.018 across pairs (1.x against 40.y), 0.011
  // across pixels, below 1e-5 for x against y of one pair (a net); independent
  // 0.014 across pairs, 0.016 across pixels, 0.005 for x against y.
  const auto n         = 1 << 14;
  const auto tolerance = 4 / std::sqrt((double)n);
  for (auto type : {sequence_type::sobol, sequence_type::independent}) {
    auto name = sequence_names[(int)type];
    // Pairs 0..npairs-1 of N samples of a pixel, drawn in order, as the
    // series of their x (index 2 pair) and y (index 2 pair + 1).
    auto series = [&](int64_t pixel, int npairs) {
      auto values = std::vector<std::vector<double>>(2 * npairs, std::vector<double>(n));
      for (auto s = 0; s < n; s++) {
        auto state = make_sequence(type, 31, pixel, (uint32_t)s, test_sobol_pairs);
        for (auto pair = 0; pair < npairs; pair++) {
          auto point              = sample_sequence2f(state, pair);
          values[2 * pair][s]     = point.x;
          values[2 * pair + 1][s] = point.y;
        }
      }
      return values;
    };
    auto pixel = series(1234, 41);
    // Pairs p != q of one pixel: x against x, y against y, x against y.
    for (auto [p, q] : {std::pair{0, 1}, std::pair{0, 7}, std::pair{3, 4},
             std::pair{1, 40}}) {
      for (auto [yp, yq] : {std::pair{0, 0}, std::pair{1, 1}, std::pair{0, 1},
               std::pair{1, 0}}) {
        auto r = correlation(pixel[2 * p + yp], pixel[2 * q + yq]);
        EXPECT_LT(std::abs(r), tolerance) << name << " pairs " << p << (yp ? ".y " : ".x ")
                                          << q << (yq ? ".y" : ".x") << ": r " << r;
      }
    }
    // x against y of one pair.
    for (auto p : {0, 7}) {
      auto r = correlation(pixel[2 * p], pixel[2 * p + 1]);
      EXPECT_LT(std::abs(r), tolerance) << name << " pair " << p << " x, y: r " << r;
    }
    // The same pair of neighbouring pixels (next, and one row of 640 down).
    for (auto neighbour : {(int64_t)1235, (int64_t)1234 + 640}) {
      auto other = series(neighbour, 6);
      for (auto pair : {0, 5}) {
        for (auto y : {0, 1}) {
          auto r = correlation(pixel[2 * pair + y], other[2 * pair + y]);
          EXPECT_LT(std::abs(r), tolerance) << name << " pixels 1234 and " << neighbour
                                            << " pair " << pair << ": r " << r;
        }
      }
    }
  }
}

TEST(sampling, pixels_have_different_points) {
  // No two of 1024 pixels share their first 16 points, nor any point.
  for (auto type : {sequence_type::sobol, sequence_type::independent}) {
    for (auto pair : {0, 3}) {
      auto first = sequence_points(type, 5, 0, 0, 16, pair);
      for (auto pixel = 1; pixel < 1024; pixel++) {
        auto points = sequence_points(type, 5, pixel, 0, 16, pair);
        auto same   = 0;
        for (auto i = 0; i < 16; i++)
          same += points[i].x == first[i].x && points[i].y == first[i].y;
        ASSERT_LT(same, 16) << "pixel " << pixel;
        EXPECT_LE(same, 1) << "pixel " << pixel;
      }
    }
  }
}

// -----------------------------------------------------------------------------
// LOW DISCREPANCY PAYS
// -----------------------------------------------------------------------------

// RMS error over 256 pixels of the 64-sample estimate of the integral of
// f(x, y) = x y e^x over [0, 1]^2, which is (integral of x e^x) / 2 = 1 / 2.
static double integration_rms_error(sequence_type type, int pair) {
  auto sum2 = 0.0;
  for (auto pixel = 0; pixel < 256; pixel++) {
    auto estimate = 0.0;
    for (auto s = 0u; s < 64; s++) {
      auto p = sequence_point(type, 77, pixel, s, pair);
      estimate += (double)p.x * p.y * std::exp((double)p.x);
    }
    estimate /= 64;
    sum2 += (estimate - 0.5) * (estimate - 0.5);
  }
  return std::sqrt(sum2 / 256);
}

TEST(sampling, sobol_beats_independent_on_smooth_integrand) {
  // 64 samples per pixel, 256 pixels. Measured RMS errors: sobol 2.54e-3
  // (pair 0) and 2.51e-3 (pair 9), independent 6.26e-2 (the expected
  // 0.531 / sqrt(64) = 6.6e-2): ratios 24.6 and 24.9. Bound: 10.
  auto independent = integration_rms_error(sequence_type::independent, 0);
  for (auto pair : {0, 9}) {
    auto sobol = integration_rms_error(sequence_type::sobol, pair);
    EXPECT_GT(independent / sobol, 10) << "pair " << pair << ": sobol " << sobol
                                       << ", independent " << independent;
  }
}
