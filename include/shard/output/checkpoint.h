// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file checkpoint.h
 * @brief Checkpoint files and restart (subsection `N - Checkpoint`): atomic per-rank files,
 *        a manifest that marks a complete checkpoint, node keys that do not depend on the
 *        partition (doc/manual/checkpoint.md).
 * @ingroup output
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/mesh/discretization.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace shard::output
{
  /**
   * @brief Writes and finds checkpoints; knows nothing of what they hold.
   *
   * A checkpoint of step n is one file per rank, `checkpoint_<n>.rank<r>.bin`, and a text
   * manifest `checkpoint_<n>.manifest` (step, time, rank count, scene fingerprint, size and
   * FNV-1a hash of every rank file). Each file is written to `<name>.tmp`, flushed to disk
   * (fsync) and renamed; the manifest is renamed last, after every rank file is in place, so a
   * checkpoint without its manifest is incomplete and never read. Restart takes the newest
   * complete checkpoint of a directory (or the manifest named), checks the hashes, the
   * fingerprint and that the files belong together, and hands every rank the payloads of all
   * rank files, so a run can restart at any rank count.
   *
   * It also maps nodes to keys that do not depend on the partition: the coarse-mesh vertex
   * index of a node (every cell of the mesh is a coarse cell, doc/manual/checkpoint.md).
   */
  class Checkpoint : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Sets the directory (default `<output directory>/checkpoint`), the fingerprint
     * of the scene (a hash of @p fingerprint, a text that describes what must not change
     * between the run that wrote a checkpoint and the one that reads it) and the node keys; with `restart from` set, finds and reads the checkpoint
     * (every rank reads every rank file).
     * @throws base::InputError naming the key and the file when the checkpoint is missing,
     * incomplete, corrupt or from another scene.
     * @note Collective.
     */
    void
    prepare(const mesh::Discretization &discretization, const std::string &output_directory,
            const std::string &fingerprint, const base::PrmSource &source);

    /// Whether a checkpoint is due after step @p step.
    bool
    is_due(const unsigned int step) const
    {
      return interval_ > 0 && step % interval_ == 0;
    }

    /**
     * @brief Writes this rank's @p payload as the checkpoint of step @p step at time @p time,
     * then (rank 0) the manifest, then removes checkpoints beyond the number kept.
     * @note Collective.
     */
    void
    write(unsigned int step, double time, const std::string &payload);

    /// Whether this run restarts from a checkpoint.
    bool
    restarting() const
    {
      return !payloads_.empty();
    }

    /// Rank count of the checkpoint read.
    unsigned int
    restart_ranks() const
    {
      return static_cast<unsigned int>(payloads_.size());
    }

    /// Whether the checkpoint read was written at the rank count of this run.
    bool
    same_rank_count() const;

    /// Payload of rank @p r of the checkpoint read.
    const std::string &
    payload(const unsigned int r) const
    {
      return payloads_.at(r);
    }

    /// Manifest path of the checkpoint read.
    const std::string &
    restart_manifest() const
    {
      return manifest_;
    }

    /// Releases the payloads read (after the restart is done).
    void
    release()
    {
      payloads_.clear();
      payloads_.shrink_to_fit();
    }

    /// Partition-independent key (coarse vertex index) of the owned node whose first DOF has
    /// local index @p local_dof.
    unsigned long long
    key_of_local_dof(unsigned int local_dof) const
    {
      return key_of_owned_[local_dof / 3];
    }

    /**
     * @brief Fills the tables of key_of_node() and node_of_key() with every rank's nodes, on the
     * first call (later calls return at once). The tables hold two entries per node of the model
     * on every rank, so only a run that writes or reads a checkpoint builds them, when it first
     * does (the node numbering does not change during a run). @note Collective.
     */
    void
    share_node_keys();

    /// Key of the node with global DOF index 3 @p node (any rank's node). Needs share_node_keys().
    unsigned long long
    key_of_node(unsigned long long node) const
    {
      if (!shared_)
        throw std::logic_error("Checkpoint::key_of_node before share_node_keys()");
      return key_of_node_.at(node);
    }

    /// Global node (global DOF / 3) of key @p key, or ~0ull when no node has it. Needs
    /// share_node_keys().
    unsigned long long
    node_of_key(unsigned long long key) const
    {
      if (!shared_)
        throw std::logic_error("Checkpoint::node_of_key before share_node_keys()");
      return key < node_of_key_.size() ? node_of_key_[key] : ~0ull;
    }

  private:
    unsigned int interval_ = 0;
    unsigned int keep_     = 2;
    std::string  directory_text_;
    std::string  restart_from_;

    MPI_Comm                        comm_ = MPI_COMM_SELF;
    std::string                     directory_, fingerprint_, manifest_;
    std::vector<std::string>        payloads_;
    std::vector<unsigned long long> key_of_owned_, key_of_node_, node_of_key_;
    /// For share_node_keys(): the first owned node, the node and key counts of the model.
    unsigned long long first_owned_node_ = 0, n_nodes_ = 0, n_keys_ = 0;
    bool               shared_ = false;

    /// Path of file @p suffix of the checkpoint of @p step in the directory.
    std::string
    path(unsigned int step, const std::string &suffix) const;
    /// Reads and checks the manifest @p manifest and its rank files (all ranks).
    void
    read(const std::string &manifest, const base::PrmSource &source);
  };
} // namespace shard::output
