// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file material_library.h
 * @brief Named material instances of subsection `C - Materials` (Peridigm style: materials are
 *        named once and assigned to bodies by name).
 * @ingroup materials
 */
#pragma once

#include <shard/materials/material.h>

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace shard::materials
{
  /**
   * @brief Holds one Material per name in `C - Materials/material names`.
   *
   * Declaration runs in stages: the names, then each name's `model`, then the model's keys.
   */
  class MaterialLibrary : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /// Builds derived data of every model.
    void
    prepare();

    /**
     * @brief Writes the resolved parameters of every material that generates them
     * (Material::write_resolved_parameters) as a .prm file; writes no file when none does.
     * @param filename The file to write.
     */
    void
    write_resolved_parameters(const std::string &filename) const;

    /// Names in input order.
    const std::vector<std::string> &
    names() const
    {
      return names_;
    }

    /// True if a material called @p name exists.
    bool
    has(const std::string &name) const
    {
      return entries_.count(name) && entries_.at(name).material;
    }

    /// The material called @p name (must exist).
    const Material &
    get(const std::string &name) const;

  private:
    struct Entry
    {
      std::string               model = "von mises";
      std::string               declared_model;
      bool                      model_parsed = false;
      std::unique_ptr<Material> material;
    };
    std::string                  names_text_ = "steel";
    std::vector<std::string>     names_      = {"steel"};
    bool                         names_declared_ = false;
    std::map<std::string, Entry> entries_;
  };
} // namespace shard::materials
