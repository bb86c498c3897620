// SPDX-License-Identifier: LGPL-2.1-or-later
// Stability and consistency of the particle formulation, through the production operator
// (SpgOperator) with a small-strain isotropic material (E = 1, nu = 0.3, rho = 1, h = 1):
// - spectral test (a): zero-mode count of the assembled stiffness of a free 6x6x6 block;
// - spectral test (b): Rayleigh quotient of the odd-even patterns (-1)^(i+j+k) e in the
//   interior of a 12x12x12 block, relative to the largest eigenvalue;
// - Galerkin patch test: boundary particles follow a linear field, the interior is solved;
// - the residual force is the exact gradient of its energy, and vanishes for linear fields;
// - the gradient correction meets the integration constraint.
// The numbers are printed for doc/theory/spg_stabilization.md.
#include <shard/particles/neighbor_build.h>
#include <shard/particles/consistent_correction.h>
#include <shard/particles/spg_operator.h>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

namespace
{
  using namespace shard::particles;

  constexpr double E = 1, nu = 0.3;
  constexpr double lambda_lame = E * nu / ((1 + nu) * (1 - 2 * nu));
  constexpr double mu          = E / (2 * (1 + nu));
  constexpr double p_modulus   = lambda_lame + 2 * mu;

  /// One form of the method under test.
  struct Form
  {
    const char        *name;
    FormulationOptions options;
    bool               is_default = false;
  };

  FormulationOptions
  make(const Smoothing s, const Stabilization st, const double alpha, const Correction correction)
  {
    FormulationOptions o;
    o.smoothing            = s;
    o.stabilization        = st;
    o.residual_coefficient = alpha;
    o.correction           = correction;
    return o;
  }
  constexpr Correction none = Correction::none, pg = Correction::petrov_galerkin, cc = Correction::consistent;

  /// Coefficients d (3 per particle) drawn uniformly from [-1e-3, 1e-3] m, reproducibly.
  std::vector<double>
  random_coefficients(const unsigned int n_particles, const unsigned int seed)
  {
    std::mt19937                           rng(seed);
    std::uniform_real_distribution<double> r(-1e-3, 1e-3);
    std::vector<double>                    d(3 * n_particles);
    for (auto &v : d)
      v = r(rng);
    return d;
  }

  /// A particle block n^3 at spacing 1 with hex-mesh nodal volumes and boundary area vectors.
  struct Block
  {
    unsigned int        n;
    ParticleCloud       cloud;
    std::vector<double> volume, area;
    LocalStencils       stencils;
    SpgOperator         op;
    CorrectionSolve     solve;

    Block(const unsigned int n_, const double dilation, const FormulationOptions &options, const double jitter = 0,
          const bool constrain_boundary = false)
      : n(n_)
    {
      std::mt19937                           rng(7);
      std::uniform_real_distribution<double> noise(-jitter, jitter);
      for (unsigned int k = 0; k < n; ++k)
        for (unsigned int j = 0; j < n; ++j)
          for (unsigned int i = 0; i < n; ++i)
            {
              const unsigned int idx[3] = {i, j, k};
              Point3             x{{double(i), double(j), double(k)}};
              double             v = 1;
              Point3             a{{0, 0, 0}};
              bool               boundary = false;
              for (unsigned int c = 0; c < 3; ++c)
                {
                  const bool lo = idx[c] == 0, hi = idx[c] == n - 1;
                  if (lo || hi)
                    {
                      v *= 0.5;
                      boundary = true;
                    }
                  else
                    x[c] += noise(rng);
                }
              // Outward area vector: per face direction c, the node's share of the boundary quads.
              for (unsigned int c = 0; c < 3; ++c)
                if (idx[c] == 0 || idx[c] == n - 1)
                  {
                    double share = 1;
                    for (unsigned int o = 0; o < 3; ++o)
                      if (o != c && (idx[o] == 0 || idx[o] == n - 1))
                        share *= 0.5;
                    a[c] = (idx[c] == 0 ? -1. : 1.) * share;
                  }
              cloud.position.push_back(x);
              cloud.spacing.push_back(Point3{{1, 1, 1}});
              cloud.interpolating.push_back(constrain_boundary && boundary ? 1 : 0);
              volume.push_back(v);
              area.insert(area.end(), a.begin(), a.end());
            }
      consistent_area_vectors();
      RkParameters params;
      params.dilation = dilation;
      std::vector<unsigned int> owned(cloud.position.size());
      for (unsigned int p = 0; p < owned.size(); ++p)
        owned[p] = p;
      stencils = build_local_stencils(cloud, owned, params);
      std::vector<double> lambda(owned.size());
      for (unsigned int p = 0; p < owned.size(); ++p)
        lambda[p] = volume[p] * p_modulus / (dilation * dilation);
      op.reinit(stencils, options, lambda);
      if (options.correction == Correction::petrov_galerkin)
        {
          const unsigned int  m = size();
          std::vector<double> c(3 * m), b(3 * m), w(m), xi(3 * m);
          op.integration_terms(volume.data(), area.data(), c.data(), b.data(), w.data());
          for (unsigned int k = 0; k < m; ++k)
            for (unsigned int i = 0; i < 3; ++i)
              xi[3 * k + i] = (b[3 * k + i] - c[3 * k + i]) / w[k];
          op.set_gradient_correction(xi);
        }
      if (options.correction == Correction::consistent)
        {
          const ConsistentCorrection correction(stencils, cloud.position, volume.data());
          CorrectionExchange         one_rank;
          one_rank.assemble = one_rank.distribute = one_rank.sum = [](std::vector<double> &) {};
          std::vector<double> lambda;
          solve = solve_consistent_correction(correction, area.data(), cloud.position,
                                              std::vector<unsigned int>(size(), 0u), 1, one_rank, lambda);
          const auto corrected = correction.corrected_gradients(lambda.data());
          std::copy(corrected.begin(), corrected.end(), stencils.g.grad.begin());
        }
    }

    unsigned int
    size() const
    {
      return cloud.position.size();
    }

    /// Replaces the area shares by the exact nodal area vectors a_J = sum over boundary quads of
    /// int N_J n dA (2x2 Gauss, exact for bilinear faces), so that sum_J a_J (x) X_J = V 1 holds
    /// also where the boundary nodes are jittered along their face.
    void
    consistent_area_vectors()
    {
      std::fill(area.begin(), area.end(), 0.);
      const auto index = [&](const unsigned int i, const unsigned int j, const unsigned int k) {
        return (k * n + j) * n + i;
      };
      const double g = 0.5 / std::sqrt(3.);
      for (unsigned int c = 0; c < 3; ++c) // face normal direction
        for (const unsigned int side : {0u, n - 1})
          for (unsigned int b = 0; b + 1 < n; ++b)
            for (unsigned int a = 0; a + 1 < n; ++a)
              {
                // Corners in the (a, b) plane of the two tangential directions t1, t2.
                const unsigned int t1 = (c + 1) % 3, t2 = (c + 2) % 3;
                unsigned int       node[4];
                const unsigned int da[4] = {0, 1, 1, 0}, db[4] = {0, 0, 1, 1};
                for (unsigned int v = 0; v < 4; ++v)
                  {
                    unsigned int idx[3];
                    idx[c]  = side;
                    idx[t1] = a + da[v];
                    idx[t2] = b + db[v];
                    node[v] = index(idx[0], idx[1], idx[2]);
                  }
                for (const double xi : {0.5 - g, 0.5 + g})
                  for (const double eta : {0.5 - g, 0.5 + g})
                    {
                      const double N[4]  = {(1 - xi) * (1 - eta), xi * (1 - eta), xi * eta, (1 - xi) * eta};
                      const double Nx[4] = {-(1 - eta), 1 - eta, eta, -eta};
                      const double Ne[4] = {-(1 - xi), -xi, xi, 1 - xi};
                      double       dx[3] = {0, 0, 0}, de[3] = {0, 0, 0};
                      for (unsigned int v = 0; v < 4; ++v)
                        for (unsigned int d = 0; d < 3; ++d)
                          {
                            dx[d] += Nx[v] * cloud.position[node[v]][d];
                            de[d] += Ne[v] * cloud.position[node[v]][d];
                          }
                      double nd[3] = {dx[1] * de[2] - dx[2] * de[1], dx[2] * de[0] - dx[0] * de[2],
                                      dx[0] * de[1] - dx[1] * de[0]};
                      const double sign = (nd[c] > 0) == (side > 0) ? 0.25 : -0.25; // weight 1/4, outward
                      for (unsigned int v = 0; v < 4; ++v)
                        for (unsigned int d = 0; d < 3; ++d)
                          area[3 * node[v] + d] += sign * N[v] * nd[d];
                    }
              }
    }

    /// The force (external minus internal, i.e. -K d) of the linear small-strain model.
    std::vector<double>
    force(const std::vector<double> &d, double *stabilization_energy = nullptr) const
    {
      const unsigned int  m = size();
      std::vector<double> u(3 * m), F(9 * m), VP(9 * m), f(3 * m, 0.);
      op.displacement(d.data(), u.data());
      op.deformation_gradient(u.data(), F.data());
      for (unsigned int p = 0; p < m; ++p)
        {
          double eps[3][3], tr = 0;
          for (unsigned int i = 0; i < 3; ++i)
            for (unsigned int j = 0; j < 3; ++j)
              eps[i][j] = 0.5 * (F[9 * p + 3 * i + j] + F[9 * p + 3 * j + i]) - (i == j ? 1. : 0.);
          tr = eps[0][0] + eps[1][1] + eps[2][2];
          for (unsigned int i = 0; i < 3; ++i)
            for (unsigned int j = 0; j < 3; ++j)
              VP[9 * p + 3 * i + j] = volume[p] * (2 * mu * eps[i][j] + (i == j ? lambda_lame * tr : 0.));
        }
      op.subtract_internal_force(VP.data(), f.data());
      double es = 0;
      if (op.options().stabilization == Stabilization::residual)
        es = op.subtract_residual_force(d.data(), f.data());
      if (stabilization_energy)
        *stabilization_energy = es;
      return f;
    }

    /// Dense stiffness K (f = -K d), mass-scaled: M^-1/2 K M^-1/2.
    Eigen::MatrixXd
    scaled_stiffness() const
    {
      const unsigned int n_dofs = 3 * size();
      Eigen::MatrixXd    K(n_dofs, n_dofs);
      std::vector<double> d(n_dofs, 0.);
      for (unsigned int c = 0; c < n_dofs; ++c)
        {
          d[c]         = 1;
          const auto f = force(d);
          d[c]         = 0;
          for (unsigned int r = 0; r < n_dofs; ++r)
            K(r, c) = -f[r] / std::sqrt(volume[r / 3] * volume[c / 3]);
        }
      return K;
    }
  };

  struct Spectrum
  {
    unsigned int small = 0; // |lambda| < 1e-4 lambda_max
    double       lowest_nonrigid = 0, lambda_max = 0, max_imag = 0, min_real = 0;
  };

  Spectrum
  spectrum(const Block &b)
  {
    const Eigen::MatrixXd             K = b.scaled_stiffness();
    Eigen::EigenSolver<Eigen::MatrixXd> solver(K, false);
    std::vector<double>               values;
    Spectrum                          s;
    for (Eigen::Index i = 0; i < solver.eigenvalues().size(); ++i)
      {
        values.push_back(std::abs(solver.eigenvalues()[i]));
        s.max_imag = std::max(s.max_imag, std::abs(solver.eigenvalues()[i].imag()));
        s.min_real = std::min(s.min_real, solver.eigenvalues()[i].real());
      }
    std::sort(values.begin(), values.end());
    s.lambda_max = values.back();
    for (const double v : values)
      s.small += v < 1e-4 * s.lambda_max;
    s.lowest_nonrigid = values[6] / s.lambda_max;
    s.max_imag /= s.lambda_max;
    s.min_real /= s.lambda_max;
    return s;
  }

  const Form default_form{"default (two-level + R2 0.1 + consistent)",
                          make(Smoothing::two_level, Stabilization::residual, 0.1, cc), true};
  const Form dni_form{"plain DNI RK", make(Smoothing::none, Stabilization::none, 0, none)};
  const Form r0_form{"plain two-level (R0)", make(Smoothing::two_level, Stabilization::none, 0, none)};
  const Form r2_form{"two-level + R2 0.1", make(Smoothing::two_level, Stabilization::residual, 0.1, none)};
} // namespace

// (a) Zero modes of a free 6x6x6 block at dilations 1.5 and 2.5.
TEST(SpgStability, FreeBlockZeroModeCount)
{
  std::printf("form | dilation | eigenvalues < 1e-4 lmax | lowest non-rigid / lmax | omega_max h / c | "
              "max |Im lambda| / lmax | min Re lambda / lmax\n");
  const Form scan[] = {dni_form,
                       r0_form,
                       r2_form,
                       {"two-level + R2 0.03", make(Smoothing::two_level, Stabilization::residual, 0.03, none)},
                       {"two-level + R2 0.1 + Petrov-Galerkin", make(Smoothing::two_level, Stabilization::residual, 0.1, pg)},
                       {"DNI + consistent", make(Smoothing::none, Stabilization::none, 0, cc)},
                       {"two-level + consistent", make(Smoothing::two_level, Stabilization::none, 0, cc)},
                       {"two-level + R2 0.03 + consistent", make(Smoothing::two_level, Stabilization::residual, 0.03, cc)},
                       default_form,
                       {"two-level + R2 0.3 + consistent", make(Smoothing::two_level, Stabilization::residual, 0.3, cc)}};
  for (const double dilation : {1.5, 2.5})
    for (const Form &form : scan)
      {
        const Block    b(6, dilation, form.options);
        const Spectrum s = spectrum(b);
        std::printf("%s | %.1f | %u | %.3e | %.3f | %.1e | %.1e\n", form.name, dilation, s.small, s.lowest_nonrigid,
                    std::sqrt(s.lambda_max / p_modulus), s.max_imag, s.min_real);
        if (form.is_default)
          {
            EXPECT_EQ(s.small, 6u) << "dilation " << dilation;
            // The stable step h / c with the safety factor 0.9 stays below 2 / omega_max.
            EXPECT_LT(0.9 * std::sqrt(s.lambda_max / p_modulus), 2.0);
            // A symmetric stiffness: real spectrum, no growing modes.
            EXPECT_LT(s.max_imag, 1e-12);
          }
      }
}

// (b) Odd-even patterns in the interior of a 12x12x12 block: energy per unit mass at the
// integration points whose whole two-hop stencil lies in the block, over lambda_max.
TEST(SpgStability, OddEvenPatternsCarryEnergy)
{
  const unsigned int n = 12;
  std::printf("form | dilation | axis | Rayleigh quotient / lmax\n");
  const Form forms[] = {dni_form,
                        r0_form,
                        r2_form,
                        {"two-level + consistent", make(Smoothing::two_level, Stabilization::none, 0, cc)},
                        {"two-level + R2 0.03 + consistent", make(Smoothing::two_level, Stabilization::residual, 0.03, cc)},
                        default_form,
                        {"two-level + R2 0.3 + consistent", make(Smoothing::two_level, Stabilization::residual, 0.3, cc)}};
  for (const double dilation : {1.5, 2.5})
    for (const Form &form : forms)
      {
        const Block        b(n, dilation, form.options);
        const unsigned int m    = b.size();
        const unsigned int skin = dilation < 2 ? 3 : 5; // two supports deep
        // Largest eigenvalue of M^-1 K by power iteration.
        std::vector<double> x(3 * m);
        std::mt19937        rng(3);
        std::normal_distribution<double> g;
        for (auto &v : x)
          v = g(rng);
        double lmax = 0;
        for (unsigned int it = 0; it < 300; ++it)
          {
            auto   f    = b.force(x);
            double norm = 0;
            for (unsigned int r = 0; r < 3 * m; ++r)
              {
                f[r] = -f[r] / b.volume[r / 3];
                norm += f[r] * f[r];
              }
            norm = std::sqrt(norm);
            double xn = 0;
            for (const double v : x)
              xn += v * v;
            lmax = norm / std::sqrt(xn);
            for (unsigned int r = 0; r < 3 * m; ++r)
              x[r] = f[r] / norm;
          }
        for (unsigned int axis = 0; axis < 3; ++axis)
          {
            std::vector<double> d(3 * m, 0.);
            for (unsigned int k = 0; k < n; ++k)
              for (unsigned int j = 0; j < n; ++j)
                for (unsigned int i = 0; i < n; ++i)
                  d[3 * ((k * n + j) * n + i) + axis] = (i + j + k) % 2 ? -1. : 1.;
            const auto f = b.force(d);
            // Interior energy from the local work -f . d restricted to interior particles equals
            // the interior energy density of the pattern, which is uniform there.
            double work = 0, mass = 0;
            for (unsigned int k = skin; k < n - skin; ++k)
              for (unsigned int j = skin; j < n - skin; ++j)
                for (unsigned int i = skin; i < n - skin; ++i)
                  {
                    const unsigned int p = (k * n + j) * n + i;
                    for (unsigned int c = 0; c < 3; ++c)
                      work -= f[3 * p + c] * d[3 * p + c];
                    mass += b.volume[p];
                  }
            const double rq = work / mass / lmax;
            std::printf("%s | %.1f | %c | %.3e\n", form.name, dilation, "xyz"[axis], rq);
            if (form.is_default)
              {
                EXPECT_GE(rq, 1e-3) << "dilation " << dilation << ", axis " << axis;
              }
          }
      }
}

// Galerkin patch test: the boundary particles interpolate and follow a linear field, the
// interior is solved statically; the interior must come out linear.
TEST(SpgStability, GalerkinPatchTest)
{
  const double H[3][3] = {{2e-3, -1e-3, 5e-4}, {3e-4, -1.5e-3, 7e-4}, {-6e-4, 2e-4, 1e-3}};
  const auto   linear  = [&](const Point3 &x, const unsigned int i) {
    return 1e-4 * (i + 1) + H[i][0] * x[0] + H[i][1] * x[1] + H[i][2] * x[2];
  };
  const Form forms[] = {dni_form,
                        r0_form,
                        r2_form,
                        {"DNI + Petrov-Galerkin", make(Smoothing::none, Stabilization::none, 0, pg)},
                        {"two-level + Petrov-Galerkin", make(Smoothing::two_level, Stabilization::none, 0, pg)},
                        {"two-level + R2 0.1 + Petrov-Galerkin", make(Smoothing::two_level, Stabilization::residual, 0.1, pg)},
                        {"DNI + consistent", make(Smoothing::none, Stabilization::none, 0, cc)},
                        {"two-level + consistent", make(Smoothing::two_level, Stabilization::none, 0, cc)},
                        default_form};
  std::printf("form | dilation | max |u - u_linear| / max |u_linear|\n");
  for (const double dilation : {1.5, 2.5})
    for (const Form &form : forms)
      {
        const Block        b(7, dilation, form.options, 0.2, true);
        const unsigned int m = b.size();
        std::vector<int>   free_index(3 * m, -1);
        std::vector<double> d(3 * m, 0.);
        unsigned int       n_free = 0;
        for (unsigned int p = 0; p < m; ++p)
          for (unsigned int i = 0; i < 3; ++i)
            {
              if (b.cloud.interpolating[p])
                d[3 * p + i] = linear(b.cloud.position[p], i);
              else
                free_index[3 * p + i] = n_free++;
            }
        // Residual r(d_free) = f(d) is affine: assemble its Jacobian column by column.
        const auto      f0 = b.force(d);
        Eigen::MatrixXd Kff(n_free, n_free);
        Eigen::VectorXd rhs(n_free);
        for (unsigned int r = 0; r < 3 * m; ++r)
          if (free_index[r] >= 0)
            rhs(free_index[r]) = -f0[r];
        for (unsigned int c = 0; c < 3 * m; ++c)
          if (free_index[c] >= 0)
            {
              d[c]         = 1;
              const auto f = b.force(d);
              d[c]         = 0;
              for (unsigned int r = 0; r < 3 * m; ++r)
                if (free_index[r] >= 0)
                  Kff(free_index[r], free_index[c]) = f[r] - f0[r];
            }
        const Eigen::VectorXd x = Kff.partialPivLu().solve(rhs);
        for (unsigned int c = 0; c < 3 * m; ++c)
          if (free_index[c] >= 0)
            d[c] = x(free_index[c]);
        std::vector<double> u(3 * b.stencils.n_j);
        b.op.displacement(d.data(), u.data());
        double err = 0, scale = 0;
        for (unsigned int p = 0; p < m; ++p)
          for (unsigned int i = 0; i < 3; ++i)
            {
              err   = std::max(err, std::abs(u[3 * p + i] - linear(b.cloud.position[p], i)));
              scale = std::max(scale, std::abs(linear(b.cloud.position[p], i)));
            }
        std::printf("%s | %.1f | %.3e\n", form.name, dilation, err / scale);
        if (form.options.correction != Correction::none)
          {
            EXPECT_LT(err / scale, 1e-6) << form.name << " at dilation " << dilation;
          }
      }
}

// The residual force is minus the gradient of its energy and vanishes for linear fields.
TEST(SpgStability, ResidualForceIsEnergyGradient)
{
  const Block        b(5, 1.5, make(Smoothing::two_level, Stabilization::residual, 0.1, none), 0.2);
  const Block        plain(5, 1.5, make(Smoothing::two_level, Stabilization::none, 0, none), 0.2);
  const unsigned int m = b.size();
  std::vector<double> d = random_coefficients(m, 11);
  // Stabilization part alone: difference of the two forms (same elastic part).
  const auto fs = b.force(d), fp = plain.force(d);
  double     max_f = 0;
  for (unsigned int c = 0; c < 3 * m; ++c)
    max_f = std::max(max_f, std::abs(fs[c] - fp[c]));
  ASSERT_GT(max_f, 0.);
  for (unsigned int c = 0; c < 3 * m; c += 7)
    {
      const double eps = 1e-6;
      double       ep, em;
      d[c] += eps;
      b.force(d, &ep);
      d[c] -= 2 * eps;
      b.force(d, &em);
      d[c] += eps;
      EXPECT_NEAR(-(ep - em) / (2 * eps), fs[c] - fp[c], 1e-6 * max_f) << "dof " << c;
    }
  // Linear field: no residual force.
  for (unsigned int p = 0; p < m; ++p)
    for (unsigned int i = 0; i < 3; ++i)
      d[3 * p + i] = 1e-3 * (i + 1) * b.cloud.position[p][(i + 1) % 3];
  double es = 1;
  const auto fl = b.force(d, &es), fpl = plain.force(d);
  EXPECT_LT(es, 1e-28);
  for (unsigned int c = 0; c < 3 * m; ++c)
    EXPECT_NEAR(fl[c], fpl[c], 1e-14);
}

// With the correction, a uniform stress gives interior forces that match the boundary integral
// sum_J a_J phi_K(X_J) (zero away from the surface), and total force zero.
TEST(SpgStability, GradientCorrectionMeetsIntegrationConstraint)
{
  const char *names[] = {"none", "Petrov-Galerkin", "consistent"};
  for (const Correction correction : {none, pg, cc})
    {
      const Block        b(6, 2.5, make(Smoothing::two_level, Stabilization::none, 0, correction), 0.2);
      const unsigned int m = b.size();
      std::vector<double> c(3 * m), bb(3 * m), w(m);
      b.op.integration_terms(b.volume.data(), b.area.data(), c.data(), bb.data(), w.data());
      // Uniform P = I: force = -(c + xi w) must equal -b.
      std::vector<double> VP(9 * m, 0.), f(3 * m, 0.);
      for (unsigned int p = 0; p < m; ++p)
        for (unsigned int i = 0; i < 3; ++i)
          VP[9 * p + 4 * i] = b.volume[p];
      b.op.subtract_internal_force(VP.data(), f.data());
      double err = 0, total[3] = {0, 0, 0};
      for (unsigned int k = 0; k < 3 * m; ++k)
        {
          err = std::max(err, std::abs(-f[k] - bb[k]));
          total[k % 3] += f[k];
        }
      std::printf("gradient correction %s: max |f_K - boundary integral| = %.3e", names[int(correction)], err);
      if (correction == cc)
        std::printf(" (CG %u iterations, defect %.2e -> %.2e, inconsistency %.1e)", b.solve.iterations,
                    b.solve.initial_defect, b.solve.final_defect, b.solve.inconsistency);
      std::printf("\n");
      if (correction == none)
        EXPECT_GT(err, 1e-3); // the uncorrected nodal integration misses the constraint
      else
        EXPECT_LT(err, 1e-10);
      for (const double t : total)
        EXPECT_LT(std::abs(t), 1e-12);
    }
}

// The coarse space of the correction solve (decision 0009) changes the preconditioner only: the
// corrected gradients are those of the Jacobi solve to the solve tolerance, the integration
// constraint holds, and the iterations drop. A jittered 16^3 block (4096 particles).
TEST(SpgStability, CoarseSpaceKeepsTheCorrectionAndCutsIterations)
{
  const Block        b(16, 2.5, make(Smoothing::two_level, Stabilization::none, 0, none), 0.2);
  const unsigned int m = b.size();
  CorrectionExchange one_rank;
  one_rank.assemble = one_rank.distribute = one_rank.sum = [](std::vector<double> &) {};
  const std::vector<unsigned int> component(m, 0u);
  std::vector<double>             grad[2];
  unsigned int                    iterations[2];
  for (const unsigned int k : {0u, 1u})
    {
      const ConsistentCorrection correction(b.stencils, b.cloud.position, b.volume.data());
      std::vector<double>        lambda;
      const auto solve = solve_consistent_correction(correction, b.area.data(), b.cloud.position, component, 1, one_rank,
                                                     lambda, 1e-11, 50000, k == 0 ? 0. : 3.);
      EXPECT_TRUE(solve.converged);
      iterations[k] = solve.iterations;
      grad[k]       = correction.corrected_gradients(lambda.data());
      std::printf("correction solve, coarse size %s: %u iterations, %u coarse functions on %u aggregates, "
                  "defect %.3e -> %.3e, inconsistency %.2e\n",
                  k == 0 ? "0 (Jacobi)" : "3", solve.iterations, solve.coarse_functions, solve.aggregates,
                  solve.initial_defect, solve.final_defect, solve.inconsistency);
      if (k == 1)
        {
          // 4096 particles in cubes of 3 spacings: 6^3 = 216 aggregates, each with a constant and
          // three linear functions, except the last layer of cubes, which holds one particle
          // layer and drops the direction across it.
          EXPECT_EQ(solve.aggregates, 216u);
          EXPECT_GT(solve.coarse_functions, 3 * solve.aggregates);
          EXPECT_LT(solve.coarse_functions, 4 * solve.aggregates);
        }
      // The integration constraint sum_I V_I (G + C)_IJ = a_J with the corrected gradients.
      std::vector<double> sum(3 * m, 0.);
      const Stencil      &g = b.stencils.g;
      for (unsigned int i = 0; i < m; ++i)
        for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
          for (unsigned int c = 0; c < 3; ++c)
            sum[3 * g.columns[e] + c] += b.volume[i] * grad[k][3 * e + c];
      double err = 0;
      for (unsigned int j = 0; j < 3 * m; ++j)
        err = std::max(err, std::abs(sum[j] - b.area[j]));
      EXPECT_LT(err, 1e-9);
    }
  double diff = 0, largest = 0;
  for (std::size_t e = 0; e < grad[0].size(); ++e)
    {
      diff    = std::max(diff, std::abs(grad[0][e] - grad[1][e]));
      largest = std::max(largest, std::abs(grad[0][e]));
    }
  std::printf("max |G_jacobi - G_coarse| / max |G| = %.2e\n", diff / largest);
  // Both solves stop at a relative defect of 1e-11 (at 1e-12 the Jacobi iteration stalls on
  // round-off here); the gradients agree to 2e-13 of the largest.
  EXPECT_LT(diff, 1e-10 * largest);
  EXPECT_LT(4 * iterations[1], iterations[0]);
}

// A patch solve of the consistent correction (the local update after a change of part of the
// particle set, issue 28): rows whose plain RK gradients did not change keep their corrected
// values (fixed), only the changed rows are corrected again, with their own multipliers. The
// result must meet the integration constraint everywhere and keep every row linearly exact,
// like the full solve, while touching a fraction of the rows. A jittered 14^3 block; the
// particles within 2 spacings of the centre move by up to 0.3 spacing.
TEST(SpgStability, PatchSolveKeepsTheConstraintWithTheOutsideFixed)
{
  const FormulationOptions options = make(Smoothing::two_level, Stabilization::none, 0, none);
  const Block              b(14, 2.5, options, 0.2);
  const unsigned int       m = b.size();
  CorrectionExchange       one_rank;
  one_rank.assemble = one_rank.distribute = one_rank.sum = [](std::vector<double> &) {};
  const std::vector<unsigned int> component(m, 0u);

  // 1. The full solve on the block: the corrected gradients of every row.
  const ConsistentCorrection full(b.stencils, b.cloud.position, b.volume.data());
  std::vector<double>        lambda;
  const auto first = solve_consistent_correction(full, b.area.data(), b.cloud.position, component, 1, one_rank, lambda,
                                                 1e-11, 50000, 3.);
  ASSERT_TRUE(first.converged);
  const std::vector<double> corrected = full.corrected_gradients(lambda.data());
  ASSERT_EQ(full.limited_rows(), 0u);

  // 2. Interior particles near the centre move (volumes and area vectors stay: they are interior).
  ParticleCloud cloud = b.cloud;
  const double  centre = 0.5 * (b.n - 1);
  unsigned int  moved  = 0;
  for (auto &x : cloud.position)
    {
      const double r = std::sqrt((x[0] - centre) * (x[0] - centre) + (x[1] - centre) * (x[1] - centre) +
                                 (x[2] - centre) * (x[2] - centre));
      if (r < 2)
        {
          x[0] += 0.3 * (1 - r / 2);
          x[2] -= 0.1 * (1 - r / 2);
          ++moved;
        }
    }
  std::vector<unsigned int> owned(m);
  for (unsigned int p = 0; p < m; ++p)
    owned[p] = p;
  RkParameters params;
  params.dilation        = 2.5;
  LocalStencils      st  = build_local_stencils(cloud, owned, params);
  const Stencil     &g0  = b.stencils.g;
  Stencil           &g   = st.g;
  ASSERT_EQ(st.n_j, m);
  for (unsigned int k = 0; k < m; ++k)
    ASSERT_EQ(st.cloud_index[k], k);

  // 3. A row is fixed when its plain gradients are those of step 1 (same columns, values equal to
  // round-off); it then takes its corrected values from step 1.
  std::vector<char> fixed(m, 0);
  unsigned int      n_fixed = 0;
  for (unsigned int i = 0; i < m; ++i)
    {
      const unsigned int b0 = g0.row_offsets[i], e0 = g0.row_offsets[i + 1];
      const unsigned int b1 = g.row_offsets[i], e1 = g.row_offsets[i + 1];
      bool               same = e1 - b1 == e0 - b0;
      double             scale = 0;
      for (unsigned int e = b0; same && e < e0; ++e)
        for (unsigned int c = 0; c < 3; ++c)
          scale = std::max(scale, std::abs(g0.grad[3 * e + c]));
      for (unsigned int k = 0; same && k < e0 - b0; ++k)
        {
          same = g.columns[b1 + k] == g0.columns[b0 + k];
          for (unsigned int c = 0; same && c < 3; ++c)
            same = std::abs(g.grad[3 * (b1 + k) + c] - g0.grad[3 * (b0 + k) + c]) <= 1e-12 * scale;
        }
      if (!same)
        continue;
      fixed[i] = 1;
      ++n_fixed;
      for (unsigned int k = 0; k < e0 - b0; ++k)
        for (unsigned int c = 0; c < 3; ++c)
          g.grad[3 * (b1 + k) + c] = corrected[3 * (b0 + k) + c];
    }
  const unsigned int n_free = m - n_fixed;
  EXPECT_GT(n_free, moved);
  EXPECT_LT(3 * n_free, m); // the patch is a small part of the block

  // 4. The patch solve, and the full solve on the moved cloud for comparison.
  const ConsistentCorrection patch(st, cloud.position, b.volume.data(), &fixed);
  const auto solve = solve_consistent_correction(patch, b.area.data(), cloud.position, component, 1, one_rank, lambda,
                                                 1e-11, 50000, 3., true);
  EXPECT_TRUE(solve.converged);
  const std::vector<double> result = patch.corrected_gradients(lambda.data());
  LocalStencils             st_full = build_local_stencils(cloud, owned, params);
  const ConsistentCorrection again(st_full, cloud.position, b.volume.data());
  std::vector<double>        lambda_full;
  const auto full_solve = solve_consistent_correction(again, b.area.data(), cloud.position, component, 1, one_rank,
                                                      lambda_full, 1e-11, 50000, 3.);
  EXPECT_TRUE(full_solve.converged);
  std::printf("patch solve: %u of %u rows corrected again (%u particles moved); %u iterations, %u coarse "
              "functions, defect %.3e -> %.3e; the full solve: %u iterations, %u coarse functions\n",
              n_free, m, moved, solve.iterations, solve.coarse_functions, solve.initial_defect, solve.final_defect,
              full_solve.iterations, full_solve.coarse_functions);

  // 5. The integration constraint sum_I V_I G_IJ = a_J over every column, and linear exactness of
  // every row: sum_J G_IJ = 0, sum_J G_IJ (x) X_J = 1.
  std::vector<double> sum(3 * m, 0.);
  double              exactness = 0;
  for (unsigned int i = 0; i < m; ++i)
    {
      double row[12] = {};
      for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
        for (unsigned int c = 0; c < 3; ++c)
          {
            const double v = result[3 * e + c];
            sum[3 * g.columns[e] + c] += b.volume[i] * v;
            row[c] += v;
            for (unsigned int d = 0; d < 3; ++d)
              row[3 + 3 * c + d] += v * cloud.position[g.columns[e]][d];
          }
      for (unsigned int c = 0; c < 3; ++c)
        {
          exactness = std::max(exactness, std::abs(row[c]));
          for (unsigned int d = 0; d < 3; ++d)
            exactness = std::max(exactness, std::abs(row[3 + 3 * c + d] - (c == d ? 1. : 0.)));
        }
    }
  double err = 0, plain_err = 0;
  std::vector<double> plain(3 * m, 0.);
  for (unsigned int i = 0; i < m; ++i)
    for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
      for (unsigned int c = 0; c < 3; ++c)
        plain[3 * g.columns[e] + c] += b.volume[i] * st_full.g.grad[3 * e + c];
  for (unsigned int j = 0; j < 3 * m; ++j)
    {
      err       = std::max(err, std::abs(sum[j] - b.area[j]));
      plain_err = std::max(plain_err, std::abs(plain[j] - b.area[j]));
    }
  std::printf("patch solve: max |sum_I V_I G_IJ - a_J| = %.3e (plain RK gradients: %.3e), linear exactness %.3e\n",
              err, plain_err, exactness);
  EXPECT_GT(plain_err, 1e-3); // the constraint is not met without the correction
  EXPECT_LT(err, 1e-9);
  EXPECT_LT(exactness, 1e-9);
  // The fixed rows keep their values; the free rows differ from the full solve's (another valid
  // correction: the smallest change of the patch rows, not of all rows).
  const std::vector<double> reference = again.corrected_gradients(lambda_full.data());
  double                    kept = 0, largest = 0, apart = 0;
  for (unsigned int i = 0; i < m; ++i)
    for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
      for (unsigned int c = 0; c < 3; ++c)
        {
          largest = std::max(largest, std::abs(result[3 * e + c]));
          if (fixed[i])
            kept = std::max(kept, std::abs(result[3 * e + c] - g.grad[3 * e + c]));
          else
            apart = std::max(apart, std::abs(result[3 * e + c] - reference[3 * e + c]));
        }
  std::printf("patch solve: max |G_patch - G_full| over the corrected rows = %.2e of max |G|\n", apart / largest);
  EXPECT_EQ(kept, 0.);
}

// The limiter of the consistent correction (doc/theory/spg_stabilization.md, "Correction
// limiter"): no entry of a row's correction exceeds 4 / l_I, and a limited row still
// differentiates linear fields exactly (sum_J G_IJ = 0, sum_J G_IJ (x) X_J = 1), because the
// row's correction is scaled as a whole. Driven with multipliers lambda of growing size on a
// jittered 6^3 block (dilation 1.5, l_I = 1 inside): small ones leave every row as the formula
// gives it, large ones limit every row.
TEST(SpgStability, CorrectionLimiterKeepsLinearExactness)
{
  const Block                b(6, 1.5, make(Smoothing::two_level, Stabilization::none, 0, none), 0.2);
  const unsigned int         m = b.size();
  const ConsistentCorrection correction(b.stencils, b.cloud.position, b.volume.data());
  const Stencil             &g = b.stencils.g;
  std::mt19937               rng(3);
  std::uniform_real_distribution<double> r(-1, 1);
  std::vector<double>                    unit(3 * m);
  for (double &v : unit)
    v = r(rng);
  for (const double size : {1e-3, 1e3})
    {
      std::vector<double> lambda(unit);
      for (double &v : lambda)
        v *= size;
      const auto   grad    = correction.corrected_gradients(lambda.data());
      const auto   limited = correction.limited_rows();
      double       worst_sum = 0, worst_moment = 0, worst_ratio = 0;
      for (unsigned int i = 0; i < m; ++i)
        {
          double l = 0;
          for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
            for (unsigned int c = 0; c < 3; ++c)
              l = std::max(l, std::abs(b.cloud.position[g.columns[e]][c] - b.cloud.position[i][c]));
          double sum[3] = {0, 0, 0}, moment[3][3] = {};
          for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
            for (unsigned int c = 0; c < 3; ++c)
              {
                const double v = grad[3 * e + c];
                worst_ratio    = std::max(worst_ratio, std::abs(v - g.grad[3 * e + c]) * l);
                sum[c] += v;
                for (unsigned int a = 0; a < 3; ++a)
                  moment[a][c] += b.cloud.position[g.columns[e]][a] * v;
              }
          for (unsigned int c = 0; c < 3; ++c)
            {
              worst_sum = std::max(worst_sum, std::abs(sum[c]));
              for (unsigned int a = 0; a < 3; ++a)
                worst_moment = std::max(worst_moment, std::abs(moment[a][c] - (a == c ? 1. : 0.)));
            }
        }
      std::printf("correction limiter, |lambda| <= %g: %u of %u rows limited, max |C| l = %.3f, "
                  "max |sum G| = %.1e, max |sum G (x) X - 1| = %.1e\n",
                  size, limited, m, worst_ratio, worst_sum, worst_moment);
      if (size < 1)
        EXPECT_EQ(limited, 0u);
      else
        EXPECT_EQ(limited, m);
      EXPECT_LE(worst_ratio, 4. * (1 + 1e-12));
      EXPECT_LT(worst_sum, 1e-10);
      EXPECT_LT(worst_moment, 1e-10);
    }
}

// After rows of A and G change in place (bonds broke), the partial refresh recomputes only what
// they reach and must give the force and residual energy of a full evaluation on the new rows,
// to the last bit (both use the same per-row sums). Every form with a correction vector or the
// residual is covered.
TEST(SpgStability, PartialRefreshEqualsFullEvaluation)
{
  for (const auto &options : {make(Smoothing::two_level, Stabilization::residual, 0.1, pg),
                              make(Smoothing::two_level, Stabilization::residual, 0.1, none),
                              make(Smoothing::none, Stabilization::residual, 0.1, none),
                              make(Smoothing::two_level, Stabilization::none, 0, pg)})
    {
      Block              b(8, 1.5, options, 0.2);
      const unsigned int m = b.size();
      std::vector<double> d = random_coefficients(m, 5);
      // A nonlinear stand-in for V P(F) that differs from point to point.
      const auto vp_of = [&](const std::vector<double> &F, std::vector<double> &VP, const unsigned int i) {
        for (unsigned int k = 0; k < 9; ++k)
          VP[9 * i + k] = (1. + 0.1 * (i % 3)) * (F[9 * i + k] - (k % 4 == 0)) + F[9 * i + k] * F[9 * i + k];
      };
      std::vector<double> u(3 * b.stencils.n_j), F(9 * b.stencils.n_i), VP(9 * b.stencils.n_i);
      const auto          full = [&](std::vector<double> &f) {
        b.op.displacement(d.data(), u.data());
        b.op.deformation_gradient(u.data(), F.data());
        for (unsigned int i = 0; i < b.stencils.n_i; ++i)
          vp_of(F, VP, i);
        f.assign(3 * b.stencils.n_k, 0.);
        b.op.subtract_internal_force(VP.data(), f.data());
        return options.stabilization == Stabilization::residual ? b.op.subtract_residual_force(d.data(), f.data()) :
                                                                  0.;
      };
      std::vector<double> f_old, f_full;
      full(f_old);
      // Rows change in place: one entry of each listed row drops, the others are rescaled.
      const std::vector<unsigned int> a_rows{1, 9, 10, 73}, g_rows{0, 10, 65};
      for (const unsigned int j : a_rows)
        {
          auto &a = b.stencils.a;
          if (a.row_offsets[j + 1] - a.row_offsets[j] < 2)
            continue;
          a.psi[a.row_offsets[j] + 1] = 0;
          for (unsigned int e = a.row_offsets[j]; e < a.row_offsets[j + 1]; ++e)
            a.psi[e] *= 1.05;
        }
      for (const unsigned int i : g_rows)
        {
          auto &g = b.stencils.g;
          for (unsigned int c = 0; c < 3; ++c)
            g.grad[3 * (g.row_offsets[i] + 1) + c] = 0;
          for (unsigned int e = 3 * g.row_offsets[i]; e < 3 * g.row_offsets[i + 1]; ++e)
            g.grad[e] *= 0.95;
        }
      // Partial refresh from the old evaluation's arrays, then the full one on the new rows.
      std::vector<double>       f_part = f_old, u_part = u, F_part = F, VP_part = VP;
      std::vector<unsigned int> changed;
      const double              e_part = b.op.refresh_internal_force(
        d.data(), u_part.data(), F_part.data(), VP_part.data(), [&](const unsigned int i) { vp_of(F_part, VP_part, i); },
        f_part.data(), a_rows, g_rows, changed);
      const double e_full = full(f_full);
      EXPECT_FALSE(changed.empty());
      EXPECT_LT(changed.size(), b.stencils.n_k) << "the refresh should not touch every coefficient";
      double largest_change = 0;
      for (unsigned int k = 0; k < f_full.size(); ++k)
        {
          largest_change = std::max(largest_change, std::abs(f_full[k] - f_old[k]));
          ASSERT_EQ(f_part[k], f_full[k]) << "coefficient entry " << k;
        }
      EXPECT_GT(largest_change, 0.) << "the row changes must change the force";
      EXPECT_EQ(e_part, e_full);
      for (unsigned int k = 0; k < F.size(); ++k)
        ASSERT_EQ(F_part[k], F[k]);
    }
}
