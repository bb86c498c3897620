// SPDX-License-Identifier: LGPL-2.1-or-later
// The shard program: run a scene, drive a material point, print the parameters, help and version.
#include <shard/base/parallel.h>
#include <shard/base/version.h>
#include <shard/driver/material_test.h>
#include <shard/simulation/simulation.h>

#include <deal.II/base/mpi.h>

#include <cstring>
#include <filesystem>
#include <iostream>

namespace
{
  const char *const usage =
    "shard: explicit impact and blast failure of concrete and steel structures.\n"
    "\n"
    "Usage:\n"
    "  shard run FILE.prm [--set \"Section/Subsection/key=value\" ...] [--threads N]\n"
    "      Runs a scene. --set overrides any parameter of the file (repeatable). --threads N runs\n"
    "      the force loops on N threads in each MPI rank (1 to 1024, default 1); the results are\n"
    "      bitwise the same for any N.\n"
    "      Writes history.csv, summary.json, parameters.prm and solution.pvd into the output directory.\n"
    "  shard print-parameters [FILE.prm] [--set ...]\n"
    "      Writes every parameter with its documentation, unit, range and default (or the value\n"
    "      given in FILE.prm). Named subsections (bodies, materials, conditions) follow FILE.prm.\n"
    "  shard material-test FILE.prm [--set ...] [--print-parameters]\n"
    "      Drives one point of a material of 'C - Materials' along the path of 'M - Material test'\n"
    "      (unconfined, triaxial, hydrostatic, cyclic, ...) on one rank. Writes history.csv,\n"
    "      summary.json, parameters.prm and material_test.png into its output directory.\n"
    "      --print-parameters lists the keys of 'C - Materials' and 'M - Material test' instead.\n"
    "  shard --help      This text.\n"
    "  shard --version   Version and git description.\n"
    "\n"
    "Run in parallel with: mpirun -np N shard run FILE.prm\n"
    "Exit codes: 0 completed, 1 bad input, 2 bad command line, 3 unstable run (material-test: a\n"
    "non-finite value from the material or a lateral stress condition without solution).\n";

  /// Reads the value of `--threads`: a whole number from 1 to base::max_threads.
  bool
  parse_threads(const std::string &text, unsigned int &threads)
  {
    if (text.empty() || text.size() > 4 || text.find_first_not_of("0123456789") != std::string::npos)
      return false;
    const unsigned long n = std::stoul(text);
    if (n < 1 || n > shard::base::max_threads)
      return false;
    threads = static_cast<unsigned int>(n);
    return true;
  }

  bool
  is_root(MPI_Comm comm)
  {
    return dealii::Utilities::MPI::this_mpi_process(comm) == 0;
  }

  /// `shard material-test FILE.prm [--set ...] [--print-parameters]` on rank 0 only.
  int
  material_test(const std::vector<std::string> &args, MPI_Comm comm)
  {
    if (!is_root(comm))
      return 0;
    const unsigned int n_ranks = dealii::Utilities::MPI::n_mpi_processes(comm);
    try
      {
        std::string              file;
        std::vector<std::string> overrides;
        bool                     print = false;
        for (unsigned int i = 1; i < args.size(); ++i)
          {
            if (args[i] == "--set" && i + 1 < args.size())
              overrides.push_back(args[++i]);
            else if (args[i].rfind("--set=", 0) == 0)
              overrides.push_back(args[i].substr(6));
            else if (args[i] == "--print-parameters")
              print = true;
            else if (file.empty() && args[i].rfind("--", 0) != 0)
              file = args[i];
            else
              {
                std::cerr << "shard: unexpected argument '" << args[i] << "'.\n\n" << usage;
                return 2;
              }
          }
        if (file.empty() && !print)
          {
            std::cerr << "shard: 'material-test' needs a parameter file.\n\n" << usage;
            return 2;
          }
        if (n_ranks > 1)
          std::cerr << "shard: material-test runs on rank 0 only; the other " << n_ranks - 1
                    << " rank(s) do nothing.\n";
        shard::base::PrmSource source = file.empty() ? shard::base::PrmSource() : shard::base::PrmSource(file);
        for (const auto &o : overrides)
          source.add_override(o);
        shard::driver::MaterialTest test;
        test.read(source);
        if (print)
          {
            test.print_parameters(std::cout);
            return 0;
          }
        const auto result = test.run(std::cout);
        if (result.exit_code != 0)
          std::cerr << "\nshard: material test stopped: " << result.message
                    << "\nThe output written before this step is intact.\n";
        else if (result.limit_point)
          std::cout << "shard: the path ended at a limit point of the material: " << result.message << "\n";
        return result.exit_code;
      }
    catch (const shard::base::CommandLineError &e)
      {
        std::cerr << "shard: " << e.what() << "\n";
        return 2;
      }
    catch (const shard::base::InputError &e)
      {
        std::cerr << "shard: input error: " << e.what() << "\n";
        return 1;
      }
    catch (const std::exception &e)
      {
        std::cerr << "shard: error: " << shard::base::exception_reason(e) << "\n";
        return 1;
      }
  }
} // namespace

int
main(int argc, char **argv)
{
  dealii::Utilities::MPI::MPI_InitFinalize mpi(argc, argv, 1);
  const MPI_Comm                           comm = MPI_COMM_WORLD;
  const std::vector<std::string>           args(argv + 1, argv + argc);
  if (args.empty() || args[0] == "--help" || args[0] == "-h" || args[0] == "help")
    {
      if (is_root(comm))
        std::cout << usage;
      return args.empty() ? 2 : 0;
    }
  if (args[0] == "--version")
    {
      if (is_root(comm))
        std::cout << "shard " << shard::version_string << " (" << shard::git_description << "), deal.II "
                  << DEAL_II_PACKAGE_VERSION << "\n";
      return 0;
    }
  if (args[0] == "material-test")
    return material_test(args, comm);
  if (args[0] != "run" && args[0] != "print-parameters")
    {
      if (is_root(comm))
        std::cerr << "shard: unknown command '" << args[0] << "'.\n\n" << usage;
      return 2;
    }

  try
    {
      std::string                 file;
      std::vector<std::string>    overrides;
      unsigned int                threads = 1;
      for (unsigned int i = 1; i < args.size(); ++i)
        {
          if (args[i] == "--threads" || args[i].rfind("--threads=", 0) == 0)
            {
              const bool        split = args[i] == "--threads";
              const std::string value = split ? (i + 1 < args.size() ? args[++i] : std::string()) : args[i].substr(10);
              if (!parse_threads(value, threads))
                {
                  if (is_root(comm))
                    std::cerr << "shard: --threads needs a whole number from 1 to " << shard::base::max_threads
                              << " (threads per MPI rank), got '" << value << "'.\n";
                  return 2;
                }
            }
          else if (args[i] == "--set" && i + 1 < args.size())
            overrides.push_back(args[++i]);
          else if (args[i].rfind("--set=", 0) == 0)
            overrides.push_back(args[i].substr(6));
          else if (file.empty() && args[i].rfind("--", 0) != 0)
            file = args[i];
          else
            {
              if (is_root(comm))
                std::cerr << "shard: unexpected argument '" << args[i] << "'.\n\n" << usage;
              return 2;
            }
        }
      if (args[0] == "run" && file.empty())
        {
          if (is_root(comm))
            std::cerr << "shard: 'run' needs a parameter file.\n\n" << usage;
          return 2;
        }
      shard::base::PrmSource source = file.empty() ? shard::base::PrmSource() : shard::base::PrmSource(file);
      for (const auto &o : overrides)
        source.add_override(o);
      if (threads != 1)
        shard::base::set_n_threads(threads);

      shard::Simulation simulation(comm);
      simulation.read(source);
      if (args[0] == "print-parameters")
        {
          if (is_root(comm))
            simulation.print_parameters(std::cout);
          return 0;
        }
      simulation.prepare();
      const auto result = simulation.run();
      if (is_root(comm))
        {
          if (!result.wrote_output)
            std::cerr << "\nshard: run stopped at step 0: " << result.message << "\nNothing was written; "
                      << simulation.output_directory() << "/ is as it was.\n";
          else
            {
              if (result.exit_code != 0)
                std::cerr << "\nshard: run stopped: " << result.message
                          << "\nThe output written before this step is intact.\n";
              std::cerr << "\nResults in " << simulation.output_directory() << "/: summary.json, history.csv, "
                        << std::filesystem::path(simulation.field_series()).filename().string()
                        << " (open in ParaView)\n";
            }
        }
      return result.exit_code;
    }
  catch (const shard::base::CommandLineError &e)
    {
      if (is_root(comm))
        std::cerr << "shard: " << e.what() << "\n";
      return 2;
    }
  catch (const shard::base::InputError &e)
    {
      if (is_root(comm))
        std::cerr << "shard: input error: " << e.what() << "\n";
      return 1;
    }
  catch (const std::exception &e)
    {
      if (is_root(comm))
        std::cerr << "shard: error: " << shard::base::exception_reason(e) << "\n";
      return 1;
    }
}
