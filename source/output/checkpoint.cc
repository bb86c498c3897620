// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/binary_archive.h>
#include <shard/base/sections.h>
#include <shard/output/checkpoint.h>

#include <deal.II/base/mpi.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>
#include <thread>

#include <fcntl.h>
#include <unistd.h>

namespace shard::output
{
  using namespace dealii;

  namespace
  {
    // 2: the contact state carries the contact normals of node-to-surface slaves.
    // 3: the global state carries the FNV-1a hashes of history.csv and fragments.csv.
    // 7: the contact state is the halo's (own and halo nodes, exchange lists; portable forces per
    //    owned node), issue 28.
    // 8: each rank writes the broken bonds and free particles it knows of (no global list),
    //    issue 28.
    constexpr const char *magic = "shard checkpoint 8";
    using base::fnv1a;

    /// Writes @p data to @p path through `path.tmp`, fsync and rename. @p pause_half: test hook
    /// that stops (sleeps) after half of the data is on disk, so a test can kill the process
    /// in the middle of a write.
    void
    write_durably(const std::string &path, const std::string &data, const bool pause_half = false)
    {
      const std::string tmp = path + ".tmp";
      const int         fd  = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd < 0)
        throw std::runtime_error("checkpoint: cannot open '" + tmp + "' for writing");
      const auto put = [&](const char *p, std::size_t n) {
        while (n > 0)
          {
            const ssize_t w = ::write(fd, p, n);
            if (w <= 0)
              {
                ::close(fd);
                throw std::runtime_error("checkpoint: cannot write '" + tmp + "'");
              }
            p += w;
            n -= static_cast<std::size_t>(w);
          }
      };
      const std::size_t half = pause_half ? data.size() / 2 : data.size();
      put(data.data(), half);
      if (pause_half)
        {
          ::fsync(fd);
          std::fprintf(stderr, "shard: test hook: paused in the checkpoint write of '%s'\n", tmp.c_str());
          std::fflush(stderr);
          std::this_thread::sleep_for(std::chrono::seconds(120));
        }
      put(data.data() + half, data.size() - half);
      if (::fsync(fd) != 0 || ::close(fd) != 0)
        throw std::runtime_error("checkpoint: cannot flush '" + tmp + "' to disk");
      std::filesystem::rename(tmp, path);
    }

    /// fsync of a directory, so that the renames in it are on disk.
    void
    sync_directory(const std::string &dir)
    {
      const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
      if (fd >= 0)
        {
          ::fsync(fd);
          ::close(fd);
        }
    }

    /// Step of a checkpoint file name `checkpoint_<step>.<rest>`, or -1.
    long long
    step_of(const std::string &name)
    {
      if (name.rfind("checkpoint_", 0) != 0)
        return -1;
      const auto dot = name.find('.', 11);
      if (dot == std::string::npos || dot == 11)
        return -1;
      const std::string digits = name.substr(11, dot - 11);
      if (!std::all_of(digits.begin(), digits.end(), [](const char c) { return c >= '0' && c <= '9'; }))
        return -1;
      return std::stoll(digits);
    }

    struct Manifest
    {
      unsigned int                step = 0, ranks = 0;
      std::string                 time, fingerprint;
      std::vector<std::string>    files;
      std::vector<std::uint64_t>  sizes, hashes;
    };

    /// Parses a manifest; returns false (with @p why) if it is not a complete one.
    bool
    parse_manifest(const std::string &path, Manifest &m, std::string &why)
    {
      std::ifstream in(path);
      if (!in)
        {
          why = "cannot be read";
          return false;
        }
      std::string line;
      if (!std::getline(in, line) || line != magic)
        {
          why = "is not a shard checkpoint manifest (first line '" + line.substr(0, 40) + "')";
          return false;
        }
      bool end = false;
      while (std::getline(in, line))
        {
          std::istringstream s(line);
          std::string        key;
          s >> key;
          if (key == "step")
            s >> m.step;
          else if (key == "time")
            s >> m.time;
          else if (key == "ranks")
            s >> m.ranks;
          else if (key == "fingerprint")
            s >> m.fingerprint;
          else if (key == "file")
            {
              std::string   name;
              std::uint64_t size = 0, hash = 0;
              s >> name >> size >> std::hex >> hash;
              m.files.push_back(name);
              m.sizes.push_back(size);
              m.hashes.push_back(hash);
            }
          else if (key == "end")
            end = true;
        }
      if (!end || m.ranks == 0 || m.files.size() != m.ranks)
        {
          why = "is incomplete";
          return false;
        }
      return true;
    }
  } // namespace

  bool
  Checkpoint::declare_parameters(ParameterHandler &prm)
  {
    if (!first_declaration())
      return false;
    prm.enter_subsection(sections::checkpoint);
    prm.add_parameter("interval", interval_,
                      "Steps between checkpoints (written at the end of every step that is a multiple of it); "
                      "0 writes none. Unit: 1. Range: >= 0.",
                      Patterns::Integer(0));
    prm.add_parameter("keep", keep_,
                      "Number of complete checkpoints kept; older ones are removed after a new one is "
                      "complete. Unit: 1. Range: >= 1.",
                      Patterns::Integer(1));
    prm.add_parameter("directory", directory_text_,
                      "Directory of the checkpoint files; empty: <K - Output/directory>/checkpoint. Relative "
                      "paths are relative to the working directory.");
    prm.add_parameter("restart from", restart_from_,
                      "Empty: a fresh start. Otherwise a checkpoint directory (the newest complete checkpoint in "
                      "it is used) or one checkpoint_<step>.manifest file: the run continues from that step. "
                      "The scene must be the one that wrote it; end time, max steps, output and checkpoint keys "
                      "may differ. Relative paths are relative to the working directory.");
    prm.leave_subsection();
    return true;
  }

  void
  Checkpoint::check_parameters(const base::PrmSource &source) const
  {
    if (!restart_from_.empty() && !std::filesystem::exists(restart_from_))
      source.fail(sections::checkpoint + "/restart from", restart_from_,
                  "no such file or directory (a checkpoint directory or a checkpoint_<step>.manifest file).");
  }

  std::string
  Checkpoint::path(const unsigned int step, const std::string &suffix) const
  {
    char name[64];
    std::snprintf(name, sizeof(name), "checkpoint_%08u", step);
    return directory_ + "/" + name + suffix;
  }

  bool
  Checkpoint::same_rank_count() const
  {
    return restart_ranks() == Utilities::MPI::n_mpi_processes(comm_);
  }

  void
  Checkpoint::prepare(const mesh::Discretization &discretization, const std::string &output_directory,
                      const std::string &fingerprint, const base::PrmSource &source)
  {
    comm_        = discretization.communicator();
    directory_   = directory_text_.empty() ? output_directory + "/checkpoint" : directory_text_;
    {
      std::ostringstream h;
      h << std::hex << std::setw(16) << std::setfill('0') << fnv1a(fingerprint);
      fingerprint_ = h.str();
    }

    // Keys: the merged-mesh vertex index of each owned node (Discretization::vertex_key(), the
    // same at any rank count). The global tables wait for share_node_keys().
    const auto &pt = *discretization.partitioner();
    key_of_owned_.assign(pt.locally_owned_size() / 3, ~0ull);
    for (const auto &cell : discretization.dof_handler().active_cell_iterators())
      if (cell->is_locally_owned() || cell->is_ghost())
        for (const unsigned int v : cell->vertex_indices())
          {
            const auto g = cell->vertex_dof_index(v, 0);
            if (pt.in_local_range(g) && key_of_owned_[pt.global_to_local(g) / 3] == ~0ull)
              key_of_owned_[pt.global_to_local(g) / 3] = discretization.vertex_key(cell->vertex_index(v));
          }
    if (std::find(key_of_owned_.begin(), key_of_owned_.end(), ~0ull) != key_of_owned_.end())
      throw std::logic_error("Checkpoint: an owned node without a vertex");
    first_owned_node_ = pt.local_range().first / 3;
    n_nodes_          = discretization.dof_handler().n_dofs() / 3;
    n_keys_           = discretization.n_global_vertices();
    shared_           = false;
    key_of_node_.clear();
    node_of_key_.clear();

    if (Utilities::MPI::this_mpi_process(comm_) == 0 && interval_ > 0)
      {
        std::error_code ec;
        std::filesystem::create_directories(directory_, ec);
        if (ec || !std::filesystem::is_directory(directory_))
          source.fail(sections::checkpoint + "/directory", directory_, "cannot create the directory (" + ec.message() + ").");
      }
    MPI_Barrier(comm_);

    payloads_.clear();
    if (restart_from_.empty())
      return;
    std::string manifest = restart_from_;
    if (std::filesystem::is_directory(restart_from_))
      {
        // The newest checkpoint of the directory. One whose manifest is damaged (it is written
        // last, atomically, so this is not an interrupted write) is refused, not skipped: the run
        // would silently continue from an older state.
        long long best = -1;
        for (const auto &entry : std::filesystem::directory_iterator(restart_from_))
          {
            const std::string name = entry.path().filename().string();
            const long long   step = step_of(name);
            if (step < 0 || name.size() < 9 || name.substr(name.size() - 9) != ".manifest" || step <= best)
              continue;
            best     = step;
            manifest = entry.path().string();
          }
        if (best < 0)
          source.fail(sections::checkpoint + "/restart from", restart_from_,
                      "the directory holds no complete checkpoint (checkpoint_<step>.manifest).");
        Manifest    m;
        std::string why;
        if (!parse_manifest(manifest, m, why))
          source.fail(sections::checkpoint + "/restart from", restart_from_,
                      "the newest checkpoint manifest '" + manifest + "' " + why +
                        ": remove it to restart from the one before, or name that one's manifest.");
      }
    read(manifest, source);
  }

  void
  Checkpoint::share_node_keys()
  {
    if (shared_)
      return;
    std::vector<unsigned long long> pairs;
    pairs.reserve(2 * key_of_owned_.size());
    for (std::size_t k = 0; k < key_of_owned_.size(); ++k)
      {
        pairs.push_back(first_owned_node_ + k);
        pairs.push_back(key_of_owned_[k]);
      }
    key_of_node_.assign(n_nodes_, ~0ull);
    node_of_key_.assign(n_keys_, ~0ull);
    for (const auto &list : Utilities::MPI::all_gather(comm_, pairs))
      for (std::size_t k = 0; k + 1 < list.size(); k += 2)
        {
          key_of_node_[list[k]]     = list[k + 1];
          node_of_key_[list[k + 1]] = list[k];
        }
    shared_ = true;
  }

  void
  Checkpoint::read(const std::string &manifest, const base::PrmSource &source)
  {
    const std::string key = sections::checkpoint + "/restart from";
    Manifest          m;
    std::string       why;
    if (!parse_manifest(manifest, m, why))
      source.fail(key, restart_from_, "the checkpoint manifest '" + manifest + "' " + why + ".");
    if (m.fingerprint != fingerprint_)
      source.fail(key, restart_from_,
                  "the checkpoint '" + manifest +
                    "' was written by another scene (its parameters or mesh differ from this one; only end "
                    "time, max steps, the output and the checkpoint keys may change).");
    const std::string dir = std::filesystem::path(manifest).parent_path().string();
    payloads_.assign(m.ranks, {});
    for (unsigned int r = 0; r < m.ranks; ++r)
      {
        const std::string file = (dir.empty() ? std::string() : dir + "/") + m.files[r];
        std::ifstream     in(file, std::ios::binary);
        if (!in)
          source.fail(key, restart_from_, "cannot read the checkpoint file '" + file + "'.");
        std::ostringstream s;
        s << in.rdbuf();
        payloads_[r] = s.str();
        if (payloads_[r].size() != m.sizes[r] || fnv1a(payloads_[r]) != m.hashes[r])
          source.fail(key, restart_from_,
                      "the checkpoint file '" + file + "' is corrupt (size " + std::to_string(payloads_[r].size()) +
                        " bytes, the manifest says " + std::to_string(m.sizes[r]) + ", or the hash differs).");
      }
    manifest_ = manifest;
  }

  void
  Checkpoint::write(const unsigned int step, const double time, const std::string &payload)
  {
    const unsigned int rank    = Utilities::MPI::this_mpi_process(comm_);
    const unsigned int n_ranks = Utilities::MPI::n_mpi_processes(comm_);
    const char        *hook    = std::getenv("SHARD_CHECKPOINT_TEST_PAUSE");
    const bool         pause   = hook != nullptr && std::strtoul(hook, nullptr, 10) == step && rank == 0;
    const std::string  file    = path(step, ".rank" + std::to_string(rank) + ".bin");
    write_durably(file, payload, pause);
    const std::vector<std::uint64_t> mine = {payload.size(), fnv1a(payload)};
    const auto                       all  = Utilities::MPI::gather(comm_, mine, 0);
    if (rank == 0)
      {
        sync_directory(directory_);
        std::ostringstream m;
        m << magic << "\n";
        m << "step " << step << "\n";
        m << "time " << std::hexfloat << time << std::defaultfloat << "\n";
        m << "ranks " << n_ranks << "\n";
        m << "fingerprint " << fingerprint_ << "\n";
        for (unsigned int r = 0; r < n_ranks; ++r)
          m << "file " << std::filesystem::path(path(step, ".rank" + std::to_string(r) + ".bin")).filename().string()
            << " " << all[r][0] << " " << std::hex << all[r][1] << std::dec << "\n";
        m << "end\n";
        write_durably(path(step, ".manifest"), m.str());
        sync_directory(directory_);

        // Keep the newest complete checkpoints; the manifest goes first, so a checkpoint is
        // never seen complete with a file missing.
        std::vector<long long> complete;
        for (const auto &entry : std::filesystem::directory_iterator(directory_))
          {
            const std::string name = entry.path().filename().string();
            if (name.size() > 9 && name.substr(name.size() - 9) == ".manifest" && step_of(name) >= 0)
              complete.push_back(step_of(name));
          }
        std::sort(complete.rbegin(), complete.rend());
        const std::vector<long long> kept(complete.begin(),
                                          complete.begin() + std::min<std::size_t>(keep_, complete.size()));
        for (const long long s : complete)
          if (std::find(kept.begin(), kept.end(), s) == kept.end())
            std::filesystem::remove(path(static_cast<unsigned int>(s), ".manifest"));
        std::vector<std::filesystem::path> stale;
        for (const auto &entry : std::filesystem::directory_iterator(directory_))
          {
            const long long s = step_of(entry.path().filename().string());
            if (s >= 0 && std::find(kept.begin(), kept.end(), s) == kept.end())
              stale.push_back(entry.path());
          }
        for (const auto &p : stale)
          std::filesystem::remove(p);
      }
  }
} // namespace shard::output
