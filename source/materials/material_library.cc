// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/sections.h>
#include <shard/materials/material_library.h>

#include <fstream>
#include <sstream>


namespace shard::materials
{
  bool
  MaterialLibrary::declare_parameters(dealii::ParameterHandler &prm)
  {
    bool added = false;
    prm.enter_subsection(sections::materials);
    if (!names_declared_)
      {
        prm.add_parameter("material names", names_text_,
                          "Comma-separated names of the materials; each has a subsection with its "
                          "'model' and the model's keys. Names use letters, digits, '_' and '-'.");
        names_declared_ = added = true;
      }
    names_ = base::split(names_text_, ',');
    for (const auto &name : names_)
      {
        auto &e = entries_[name];
        prm.enter_subsection(name);
        if (!e.model_parsed && e.declared_model.empty())
          {
            // Stage 2: the model key; its value is known after the next parse.
            prm.add_parameter("model", e.model, "Constitutive model of this material.",
                              dealii::Patterns::Selection(material_model_names()));
            e.declared_model = "?";
            added            = true;
          }
        else if (!e.model_parsed)
          {
            // Stage 3: the model's own keys.
            e.model_parsed = true;
            e.material     = create_material(e.model);
            e.material->declare_parameters(prm);
            e.declared_model = e.model;
            added            = true;
          }
        prm.leave_subsection();
      }
    prm.leave_subsection();
    return added;
  }

  void
  MaterialLibrary::check_parameters(const base::PrmSource &source) const
  {
    const std::string top = sections::materials + "/";
    base::check_names(source, top + "material names", names_text_, names_, false);
    for (const auto &name : names_)
      {
        const auto &e = entries_.at(name);
        if (e.declared_model != e.model)
          source.fail(top + name + "/model", e.model,
                      "the model changed after its keys were declared (set 'model' once).");
        e.material->check_parameters(source, top + name);
      }
  }

  void
  MaterialLibrary::prepare()
  {
    for (const auto &name : names_)
      entries_.at(name).material->prepare();
  }

  const Material &
  MaterialLibrary::get(const std::string &name) const
  {
    return *entries_.at(name).material;
  }

  void
  MaterialLibrary::write_resolved_parameters(const std::string &filename) const
  {
    std::ostringstream body;
    for (const auto &name : names_)
      {
        std::ostringstream one;
        entries_.at(name).material->write_resolved_parameters(one);
        if (!one.str().empty())
          body << "  subsection " << name << "\n" << one.str() << "  end\n";
      }
    if (body.str().empty())
      return;
    std::ofstream out(filename);
    out << "# Resolved parameters of the models that generate them (doc/materials/kcc.md).\n"
        << "# Paste a subsection into the scene to freeze or edit the generated values.\n"
        << "subsection C - Materials\n"
        << body.str() << "end\n";
  }
} // namespace shard::materials
