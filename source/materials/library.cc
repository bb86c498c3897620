// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file library.cc
 * @brief The registry of material models: every model is registered here and nowhere else.
 */
#include <shard/materials/elastic.h>
#include <shard/materials/kcc.h>
#include <shard/materials/material.h>
#include <shard/materials/von_mises.h>


namespace shard::materials
{
  namespace
  {
    /// One registry entry: the name used in `C - Materials/<name>/model` and a factory.
    struct Entry
    {
      const char *name;
      std::unique_ptr<Material> (*create)();
    };

    template <class Model>
    std::unique_ptr<Material>
    make()
    {
      return std::make_unique<Model>();
    }

    /// All models, in the order shown to the user.
    constexpr Entry registry[] = {
      {"elastic", &make<Elastic>},
      {"von mises", &make<VonMises>},
      {"kcc", &make<KccConcrete>},
      {"rigid", &make<Rigid>},
    };
  } // namespace

  std::unique_ptr<Material>
  create_material(const std::string &model_name)
  {
    for (const Entry &entry : registry)
      if (model_name == entry.name)
        return entry.create();
    return nullptr;
  }

  std::string
  material_model_names()
  {
    std::string names;
    for (const Entry &entry : registry)
      {
        if (!names.empty())
          names += '|';
        names += entry.name;
      }
    return names;
  }
} // namespace shard::materials
