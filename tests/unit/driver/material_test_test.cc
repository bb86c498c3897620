// SPDX-License-Identifier: LGPL-2.1-or-later
// Unit tests of the material point driver (`shard material-test`, doc/manual/materials.md,
// "Material point driver"): the path control against closed forms of the models "elastic" and
// "von mises", the failure exits, the input checks and the files written.
#include <shard/base/parameters.h>
#include <shard/driver/material_test.h>
#include <shard/materials/material.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace
{
  using namespace shard;
  using driver::LoadPath;
  using driver::PathControl;
  using driver::PointRecord;
  using materials::Material;

  /// Declares @p model in `C - Materials/steel`, parses @p text there, checks and prepares.
  std::unique_ptr<Material>
  make(const std::string &model, const std::string &text = "")
  {
    std::unique_ptr<Material> material = materials::create_material(model);
    EXPECT_TRUE(material != nullptr);
    dealii::ParameterHandler prm;
    prm.enter_subsection("C - Materials");
    prm.enter_subsection("steel");
    material->declare_parameters(prm);
    prm.parse_input_from_string(text);
    prm.leave_subsection();
    prm.leave_subsection();
    material->check_parameters(base::PrmSource(), "C - Materials/steel");
    material->prepare();
    return material;
  }

  /// Every record of a drive, and its result.
  struct Drive
  {
    std::vector<PointRecord> rows;
    driver::DriveResult      result;
  };

  Drive
  drive(const Material &material, const PathControl &control)
  {
    Drive d;
    d.result = driver::drive_material_point(material, control, [&](const PointRecord &p) { d.rows.push_back(p); });
    return d;
  }

  PathControl
  control(const LoadPath path, const std::vector<double> &targets, const double increment = 1e-4)
  {
    PathControl c;
    c.path             = path;
    c.targets          = targets;
    c.strain_increment = increment;
    c.strain_rate      = 1e-3;
    return c;
  }

  /// The driver's stress tolerance: 1e-9 max(largest normal stress magnitude, 1 MPa).
  double
  stress_tolerance(const PointRecord &p)
  {
    return 1e-9 * std::max({std::abs(p.stress[0]), std::abs(p.stress[1]), std::abs(p.stress[2]), 1e6});
  }

  /// Elastic constants, written out independently of the code.
  struct Elastic
  {
    double E, nu, K, G;
  };
  Elastic
  elastic(const double E, const double nu)
  {
    return {E, nu, E / (3. * (1. - 2. * nu)), E / (2. * (1. + nu))};
  }

  const std::string concrete_like = "young's modulus = 30e9\nset poisson's ratio = 0.2\n";

  // ---------------------------------------------------------------------------------------------
  // elastic: exactly linear in logarithmic strain (p = -K ln J, hypoelastic deviator), so every
  // path has a closed form: sigma = K tr(eps) I + 2 G dev(eps).

  TEST(MaterialTestDriver, ElasticUnconfinedCompressionMatchesClosedForm)
  {
    for (const auto &[text, E, nu] : {std::tuple<std::string, double, double>{"", 210e9, 0.3},
                                      {"set " + concrete_like, 30e9, 0.2}})
      {
        const auto material = make("elastic", text);
        const auto d        = drive(*material, control(LoadPath::unconfined_compression, {-0.01}));
        ASSERT_EQ(d.result.exit_code, 0) << d.result.message;
        ASSERT_EQ(d.result.steps, 100u);
        ASSERT_EQ(d.rows.size(), 101u);
        for (const auto &p : d.rows)
          {
            EXPECT_NEAR(p.stress[0], E * p.strain[0], 1e-8 * E * std::abs(p.strain[0])) << "step " << p.step;
            EXPECT_NEAR(p.strain[1], -nu * p.strain[0], 1e-8 * std::abs(p.strain[0])) << "step " << p.step;
            EXPECT_EQ(p.strain[1], p.strain[2]);
            EXPECT_LE(std::abs(p.stress[1]), stress_tolerance(p)) << "step " << p.step;
            EXPECT_LE(std::abs(p.stress[2]), stress_tolerance(p)) << "step " << p.step;
            EXPECT_EQ(p.stress[3], 0.);
            EXPECT_EQ(p.stress[5], 0.);
            EXPECT_NEAR(p.q(), std::abs(p.stress[0]), 1e-8 * std::abs(p.stress[0]) + 1e-3);
          }
        EXPECT_EQ(d.rows.back().strain[0], -0.01);
        EXPECT_NEAR(d.rows.back().stress[0], -0.01 * E, 1e-8 * 0.01 * E);
        // dt = increment / rate = 0.1 s, 100 steps.
        EXPECT_NEAR(d.rows.back().time, 10., 1e-10);
        EXPECT_NEAR(d.rows[1].time, 0.1, 1e-14);
      }
  }

  TEST(MaterialTestDriver, ElasticTensionAndCyclicFollowTheSameLine)
  {
    const Elastic m        = elastic(210e9, 0.3);
    const auto    material = make("elastic");
    for (const auto &c : {control(LoadPath::uniaxial_tension, {0.005}),
                          control(LoadPath::cyclic, {-0.002, 0.001, -0.003, -0.0015})})
      {
        const auto d = drive(*material, c);
        ASSERT_EQ(d.result.exit_code, 0) << d.result.message;
        // Absolute floors for the rows where the cyclic path passes through 0.
        for (const auto &p : d.rows)
          {
            EXPECT_NEAR(p.stress[0], m.E * p.strain[0], 1e-8 * m.E * std::abs(p.strain[0]) + 1e-3);
            EXPECT_NEAR(p.strain[1], -m.nu * p.strain[0], 1e-8 * std::abs(p.strain[0]) + 1e-17);
            EXPECT_LE(std::abs(p.stress[1]), stress_tolerance(p));
          }
        // Every target is hit exactly at the end of its leg (legs of 0.005; 0.002, 0.003, 0.004,
        // 0.0015 in steps of 1e-4); no step is longer than 1e-4.
        const std::vector<unsigned int> ends =
          c.path == LoadPath::uniaxial_tension ? std::vector<unsigned int>{50} : std::vector<unsigned int>{20, 50, 90, 105};
        ASSERT_EQ(d.rows.size(), ends.back() + 1);
        for (unsigned int k = 0; k < ends.size(); ++k)
          EXPECT_EQ(d.rows[ends[k]].strain[0], c.targets[k]);
        for (std::size_t k = 1; k < d.rows.size(); ++k)
          EXPECT_LE(std::abs(d.rows[k].strain[0] - d.rows[k - 1].strain[0]), 1e-4 * (1 + 1e-9));
      }
  }

  TEST(MaterialTestDriver, ElasticTriaxialKeepsConfinement)
  {
    const Elastic m        = elastic(30e9, 0.2);
    const auto    material = make("elastic", "set " + concrete_like);
    auto          c        = control(LoadPath::triaxial_compression, {-0.002});
    c.confinement          = 50e6;
    c.strain_increment     = 2e-5;
    const auto d           = drive(*material, c);
    ASSERT_EQ(d.result.exit_code, 0) << d.result.message;
    const unsigned int h = d.result.hydrostatic_steps;
    // ln J = -p/K = -50e6 / 16.67e9 = -0.003 in steps of 2e-5: 150 steps, the last one solved.
    ASSERT_EQ(h, static_cast<unsigned int>(std::ceil(50e6 / m.K / 2e-5 - 1e-6)));
    ASSERT_EQ(d.result.steps, h + 100);
    for (unsigned int k = 0; k <= h; ++k)
      {
        const auto &p = d.rows[k];
        EXPECT_EQ(p.strain[0], p.strain[1]);
        EXPECT_EQ(p.strain[0], p.strain[2]);
        EXPECT_NEAR(p.pressure(), -m.K * p.volumetric_strain(), 1e-9 * m.K * std::abs(p.volumetric_strain()));
      }
    const PointRecord start = d.rows[h];
    EXPECT_NEAR(start.pressure(), 50e6, 1e-9 * 50e6);
    EXPECT_NEAR(start.volumetric_strain(), -50e6 / m.K, 1e-9 * 50e6 / m.K);
    for (unsigned int k = h + 1; k < d.rows.size(); ++k)
      {
        const auto  &p  = d.rows[k];
        const double de = p.strain[0] - start.strain[0];
        EXPECT_NEAR(p.stress[1], -50e6, stress_tolerance(p)) << "step " << p.step;
        EXPECT_NEAR(p.stress[2], -50e6, stress_tolerance(p)) << "step " << p.step;
        EXPECT_NEAR(p.stress[0], -50e6 + m.E * de, 1e-8 * std::abs(p.stress[0])) << "step " << p.step;
        EXPECT_NEAR(p.strain[1] - start.strain[1], -m.nu * de, 1e-8 * std::abs(de)) << "step " << p.step;
      }
    // The target is measured from the start of the axial phase.
    EXPECT_NEAR(d.rows.back().strain[0] - start.strain[0], -0.002, 1e-15);
  }

  TEST(MaterialTestDriver, ElasticHydrostaticPressureFromVolume)
  {
    const Elastic m        = elastic(210e9, 0.3);
    const auto    material = make("elastic");
    const auto    d        = drive(*material, control(LoadPath::hydrostatic, {-0.03, -0.01}, 1e-3));
    ASSERT_EQ(d.result.exit_code, 0) << d.result.message;
    ASSERT_EQ(d.result.steps, 50u);
    double largest = 0;
    for (const auto &p : d.rows)
      {
        EXPECT_EQ(p.strain[0], p.strain[1]);
        EXPECT_EQ(p.strain[0], p.strain[2]);
        EXPECT_NEAR(p.pressure(), -m.K * p.volumetric_strain(), 1e-12 * m.K * 0.03);
        EXPECT_LE(p.q(), 1e-9 * std::abs(p.pressure()) + 1e-6);
        largest = std::max(largest, p.pressure());
      }
    EXPECT_NEAR(largest, 0.03 * m.K, 1e-12 * 0.03 * m.K);
    EXPECT_NEAR(d.rows[30].volumetric_strain(), -0.03, 1e-15);
    EXPECT_NEAR(d.rows.back().volumetric_strain(), -0.01, 1e-15);
    EXPECT_NEAR(d.rows.back().pressure(), 0.01 * m.K, 1e-12 * 0.01 * m.K);
  }

  TEST(MaterialTestDriver, ElasticEqualBiaxialMatchesClosedForm)
  {
    const Elastic m        = elastic(30e9, 0.2);
    const auto    material = make("elastic", "set " + concrete_like);
    const auto    d        = drive(*material, control(LoadPath::equal_biaxial_compression, {-0.003}));
    ASSERT_EQ(d.result.exit_code, 0) << d.result.message;
    for (const auto &p : d.rows)
      {
        const double e = p.strain[0];
        EXPECT_EQ(p.strain[1], e);
        EXPECT_NEAR(p.stress[0], m.E * e / (1 - m.nu), 1e-8 * m.E * std::abs(e));
        EXPECT_NEAR(p.stress[1], m.E * e / (1 - m.nu), 1e-8 * m.E * std::abs(e));
        EXPECT_LE(std::abs(p.stress[2]), stress_tolerance(p));
        EXPECT_NEAR(p.strain[2], -2 * m.nu * e / (1 - m.nu), 1e-8 * std::abs(e));
      }
  }

  TEST(MaterialTestDriver, UnevenLegsAreCutIntoEqualSteps)
  {
    const auto material = make("elastic");
    auto       c        = control(LoadPath::unconfined_compression, {-0.00105, -0.0005});
    c.strain_rate       = 1e-2;
    const auto d        = drive(*material, c);
    ASSERT_EQ(d.result.exit_code, 0);
    // 0.00105 / 1e-4 -> 11 steps, 0.00055 / 1e-4 -> 6 steps.
    ASSERT_EQ(d.result.steps, 17u);
    EXPECT_EQ(d.rows[11].strain[0], -0.00105);
    EXPECT_EQ(d.rows[17].strain[0], -0.0005);
    EXPECT_NEAR(d.rows[1].strain[0], -0.00105 / 11, 1e-18);
    // time = path length / rate.
    EXPECT_NEAR(d.rows.back().time, (0.00105 + 0.00055) / 1e-2, 1e-14);
  }

  // ---------------------------------------------------------------------------------------------
  // von mises: uniaxial stress with proportional flow, eps_xx = sigma_xx/E + eps_p_xx,
  // eps_p = e_p (-1, 1/2, 1/2) in compression, |sigma_xx| = sigma_y(e_p).

  TEST(MaterialTestDriver, VonMisesUnconfinedCompressionPlateauAtYieldStress)
  {
    const Elastic m        = elastic(210e9, 0.3);
    const auto    material = make("von mises", "set hardening table = 0 400e6\n");
    const auto    d        = drive(*material, control(LoadPath::unconfined_compression, {-0.01}, 2e-5));
    ASSERT_EQ(d.result.exit_code, 0) << d.result.message;
    const int    slot  = material->state_slot(materials::slot::plastic_strain);
    const double yield = 400e6 / m.E;
    unsigned int n_plastic = 0;
    for (const auto &p : d.rows)
      {
        const double e = -p.strain[0];
        EXPECT_LE(std::abs(p.stress[1]), stress_tolerance(p)) << "step " << p.step;
        if (e <= yield * (1 - 1e-9))
          {
            EXPECT_NEAR(p.stress[0], -m.E * e, 1e-8 * m.E * e);
            EXPECT_EQ(p.state[slot], 0.);
            continue;
          }
        ++n_plastic;
        const double ep = e - yield;
        EXPECT_NEAR(p.stress[0], -400e6, 1e-8 * 400e6) << "step " << p.step;
        EXPECT_NEAR(p.q(), 400e6, 1e-8 * 400e6) << "step " << p.step;
        EXPECT_NEAR(p.state[slot], ep, 1e-8 * e) << "step " << p.step;
        EXPECT_NEAR(p.strain[1], m.nu * yield + 0.5 * ep, 1e-8 * e) << "step " << p.step;
      }
    EXPECT_GT(n_plastic, 350u);
  }

  TEST(MaterialTestDriver, VonMisesTriaxialAndTensionWithLinearHardening)
  {
    const Elastic m  = elastic(210e9, 0.3);
    const double  s0 = 400e6, H = 100e6;
    const auto    material = make("von mises", "set hardening table = 0 400e6; 1 500e6\n");
    const int     slot     = material->state_slot(materials::slot::plastic_strain);
    const auto    closed   = [&](const double e) {
      const double ep = (e - s0 / m.E) / (1 + H / m.E);
      return std::pair<double, double>{ep, s0 + H * ep};
    };

    auto c        = control(LoadPath::triaxial_compression, {-0.02});
    c.confinement = 100e6;
    const auto t  = drive(*material, c);
    ASSERT_EQ(t.result.exit_code, 0) << t.result.message;
    const auto &start = t.rows[t.result.hydrostatic_steps];
    EXPECT_NEAR(start.pressure(), 100e6, 1e-9 * 100e6);
    EXPECT_EQ(start.state[slot], 0.);
    const auto [ep, sy] = closed(0.02);
    const auto &end     = t.rows.back();
    // The lateral stress stays at -confinement, the axial stress exceeds it by sigma_y(e_p).
    EXPECT_NEAR(end.stress[1], -100e6, stress_tolerance(end));
    EXPECT_NEAR(end.stress[0], -100e6 - sy, 1e-9 * sy);
    EXPECT_NEAR(end.state[slot], ep, 1e-9 * ep);
    EXPECT_NEAR(end.q(), sy, 1e-9 * sy);

    const auto u = drive(*material, control(LoadPath::uniaxial_tension, {0.02}));
    ASSERT_EQ(u.result.exit_code, 0) << u.result.message;
    EXPECT_NEAR(u.rows.back().stress[0], sy, 1e-9 * sy);
    EXPECT_NEAR(u.rows.back().state[slot], ep, 1e-9 * ep);
    EXPECT_NEAR(u.rows.back().strain[1], -m.nu * sy / m.E - 0.5 * ep, 1e-9);
  }

  TEST(MaterialTestDriver, VonMisesCyclicReversesToTensileYield)
  {
    const Elastic m        = elastic(210e9, 0.3);
    const auto    material = make("von mises", "set hardening table = 0 400e6\n");
    const auto    d        = drive(*material, control(LoadPath::cyclic, {-0.004, 0.004}));
    ASSERT_EQ(d.result.exit_code, 0) << d.result.message;
    const int    slot  = material->state_slot(materials::slot::plastic_strain);
    const double yield = 400e6 / m.E;
    EXPECT_NEAR(d.rows[40].stress[0], -400e6, 1e-8 * 400e6);
    EXPECT_NEAR(d.rows.back().stress[0], 400e6, 1e-8 * 400e6);
    // Plastic strain of the loading leg plus that of the reversed leg (elastic range 2 sigma_y).
    EXPECT_NEAR(d.rows.back().state[slot], (0.004 - yield) + (0.008 - 2 * yield), 1e-8);
  }

  // ---------------------------------------------------------------------------------------------
  // Failures: models written here, not registered.

  /// Linear elastic (lambda = mu = 1e10 Pa) until J < 0.999, then a NaN stress_xx; or, with
  /// constant = true, a constant stress of -1 MPa whatever the strain.
  class TestModel : public Material
  {
  public:
    explicit TestModel(const bool constant)
      : constant_(constant)
    {}
    std::string
    model_name() const override
    {
      return "test";
    }
    void
    declare_parameters(dealii::ParameterHandler &) override
    {}
    void
    check_parameters(const base::PrmSource &, const std::string &) const override
    {}
    void
    prepare() override
    {}
    double
    density() const override
    {
      return 1000.;
    }
    double
    initial_wave_speed() const override
    {
      return 1000.;
    }
    std::array<double, 2>
    elastic_moduli() const override
    {
      return {{1e10 + 2. / 3. * 1e10, 1e10}};
    }
    std::vector<std::string>
    state_slot_names() const override
    {
      return {"dummy slot"};
    }
    void
    update(const materials::PointBatch &b) const override
    {
      const double mu = 1e10, lambda = 1e10;
      const double tr = b.strain_increment[0] + b.strain_increment[1] + b.strain_increment[2];
      for (unsigned int c = 0; c < 3; ++c)
        b.stress[c] = constant_ ? -1e6 : b.stress[c] + lambda * tr + 2 * mu * b.strain_increment[c];
      if (!constant_ && b.relative_volume[0] < 0.999)
        b.stress[0] = std::numeric_limits<double>::quiet_NaN();
      b.wave_speed[0] = 1000.;
    }

  private:
    bool constant_;
  };

  TEST(MaterialTestDriver, NonFiniteStressStopsWithExitCode3)
  {
    const TestModel model(false);
    const auto      d = drive(model, control(LoadPath::unconfined_compression, {-0.01}));
    EXPECT_EQ(d.result.exit_code, 3);
    // lambda = mu: nu = 1/4, ln J = eps_xx / 2 < ln 0.999 from eps_xx = -0.002 on (step 21).
    EXPECT_NE(d.result.message.find("step 21 "), std::string::npos) << d.result.message;
    EXPECT_NE(d.result.message.find("non-finite stress_xx"), std::string::npos) << d.result.message;
    EXPECT_EQ(d.result.steps, 20u);
    EXPECT_EQ(d.rows.size(), 21u);
    EXPECT_NEAR(d.rows.back().strain[1], 0.25 * 0.002, 1e-12);
  }

  TEST(MaterialTestDriver, UnreachableLateralStressEndsThePathAtALimitPoint)
  {
    // No lateral strain gives the lateral stress: a limit point, reported, not a model failure.
    const TestModel model(true);
    const auto      d = drive(model, control(LoadPath::unconfined_compression, {-0.01}));
    EXPECT_EQ(d.result.exit_code, 0);
    EXPECT_TRUE(d.result.limit_point);
    EXPECT_NE(d.result.message.find("step 1 "), std::string::npos) << d.result.message;
    EXPECT_NE(d.result.message.find("cannot bracket"), std::string::npos) << d.result.message;
    EXPECT_EQ(d.rows.size(), 1u);
  }

  // ---------------------------------------------------------------------------------------------
  // MaterialTest: the parameter file, its checks and the files written.

  /// A fresh directory under the system temporary directory.
  std::filesystem::path
  temporary_directory()
  {
    std::string pattern = (std::filesystem::temp_directory_path() / "shard_material_test_XXXXXX").string();
    EXPECT_NE(mkdtemp(pattern.data()), nullptr);
    return pattern;
  }

  const std::string scene = R"(subsection C - Materials
  set material names = steel, glass
  subsection steel
    set model = von mises
  end
  subsection glass
    set model = elastic
  end
end
subsection M - Material test
  set material = steel
  set strain targets = -0.004
  set strain increment = 1e-4
  set plot = false
end
)";

  /// Reads @p text (written to a file in @p dir) with extra --set @p overrides.
  void
  read(driver::MaterialTest &test, const std::filesystem::path &dir, const std::vector<std::string> &overrides)
  {
    const std::string file = (dir / "test.prm").string();
    std::ofstream(file) << scene;
    base::PrmSource source(file);
    for (const auto &o : overrides)
      source.add_override(o);
    test.read(source);
  }

  TEST(MaterialTestProgram, RejectsBadKeysNamingThem)
  {
    const auto dir = temporary_directory();
    for (const auto &[set, key] : std::vector<std::pair<std::string, std::string>>{
           {"material=concrete", "material"},
           {"strain targets=-0.01 x", "strain targets"},
           {"strain targets=0.01", "strain targets"},
           {"strain targets=0", "strain targets"},
           {"strain increment=0", "strain increment"},
           {"strain increment=1e-10", "strain increment"},
           {"strain rate=0", "strain rate"},
           {"confinement=1e6", "confinement"},
           {"characteristic length=-1", "characteristic length"},
           {"output directory=", "output directory"}})
      {
        driver::MaterialTest test;
        try
          {
            read(test, dir, {"M - Material test/" + set});
            ADD_FAILURE() << "accepted " << set;
          }
        catch (const base::InputError &error)
          {
            EXPECT_NE(std::string(error.what()).find("M - Material test/" + key + " = "), std::string::npos)
              << error.what();
          }
      }
    // Tension targets are fine for tension, and confinement for the triaxial path.
    driver::MaterialTest tension;
    read(tension, dir, {"M - Material test/path=uniaxial tension", "M - Material test/strain targets=0.01"});
    EXPECT_EQ(tension.control().path, LoadPath::uniaxial_tension);
    driver::MaterialTest triaxial;
    read(triaxial, dir,
         {"M - Material test/path=triaxial compression", "M - Material test/confinement=2e7",
          "M - Material test/strain targets=-0.001, -0.0005 -0.002"});
    EXPECT_EQ(triaxial.control().confinement, 2e7);
    EXPECT_EQ(triaxial.control().targets, (std::vector<double>{-0.001, -0.0005, -0.002}));
    std::filesystem::remove_all(dir);
  }

  TEST(MaterialTestProgram, WritesHistorySummaryAndParameters)
  {
    const auto           dir = temporary_directory();
    driver::MaterialTest test;
    read(test, dir, {"M - Material test/output directory=" + (dir / "out").string()});
    std::ostringstream log;
    const auto         result = test.run(log);
    ASSERT_EQ(result.exit_code, 0) << result.message;
    EXPECT_EQ(result.steps, 40u);
    EXPECT_NE(log.str().find("40 steps, completed"), std::string::npos) << log.str();

    std::ifstream            history(dir / "out" / "history.csv");
    std::string              line;
    std::vector<std::string> lines;
    while (std::getline(history, line))
      lines.push_back(line);
    ASSERT_EQ(lines.size(), 42u);
    EXPECT_EQ(lines[0], "time,step,strain_xx,strain_yy,strain_zz,volumetric_strain,stress_xx,stress_yy,stress_zz,"
                        "pressure,q,wave_speed,effective_plastic_strain,failed,effective_strain_rate");
    // dt = 1e-4 / 1e-5 1/s = 10 s.
    EXPECT_EQ(lines.back().substr(0, 16), "400,40,-0.004,0.");

    std::ifstream     summary_file(dir / "out" / "summary.json");
    const std::string summary((std::istreambuf_iterator<char>(summary_file)), std::istreambuf_iterator<char>());
    for (const char *key : {"\"path\": \"unconfined compression\"", "\"material\": \"steel\"",
                            "\"model\": \"von mises\"", "\"steps\": 40", "\"peak_compressive_axial_stress\": 400",
                            "\"peak_tensile_axial_stress\": 0", "\"peak_q\": 400", "\"peak_pressure\": 133",
                            "\"final_strain_xx\": -0.004", "\"effective plastic strain\": 0.00209"})
      EXPECT_NE(summary.find(key), std::string::npos) << key << " not in\n" << summary;
    EXPECT_TRUE(std::filesystem::exists(dir / "out" / "parameters.prm"));
    EXPECT_FALSE(std::filesystem::exists(dir / "out" / "material_test.png"));
    std::filesystem::remove_all(dir);
  }
} // namespace
