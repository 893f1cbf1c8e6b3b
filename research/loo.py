"""Leave-one-out choice shared by research/cv-select.py and research/k-rules.py."""
import statistics as st


def choose_without(err, names):
    """err[name][i]: the error of option `name` on sample i. For every sample, the option with the
    lowest mean error on the other samples (the first of `names` wins ties): a list of names."""
    count = len(err[names[0]])
    return [min(names, key=lambda n: (st.mean(e for j, e in enumerate(err[n]) if j != i),
                                      names.index(n)))
            for i in range(count)]
